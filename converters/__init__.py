"""Converters from the challenge's on-disk formats to cldet's frames (one module per source format).

``converters.mmaud`` streams the MMAUD / UG2+ challenge layout
(``ROOT/{train,val,test}/seqNNNN/<modality>/<stamp>.npy``).
"""
