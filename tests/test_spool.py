"""The on-disk list that holds annotate's per-frame results until they are written."""

from __future__ import annotations

from contextlib import closing

import numpy as np
import pytest

from cldet.io.spool import Spool


def test_items_come_back_equal_in_any_order() -> None:
    rng = np.random.default_rng(0)
    items = [
        (k, rng.normal(size=(int(rng.integers(0, 50)), 3)).astype(np.float32)) for k in range(40)
    ]
    with closing(Spool[tuple[int, np.ndarray]]()) as spool:
        for item in items:
            spool.append(item)
        assert len(spool) == len(items)
        for k in (39, 0, 17, -1, -40):
            assert spool[k][0] == items[k][0]
            np.testing.assert_array_equal(spool[k][1], items[k][1])
        spool.append((99, np.zeros((0, 3), np.float32)))  # appending after reads
        assert [i for i, _ in spool] == [*range(40), 99]
        assert [i for i, _ in spool[38:]] == [38, 39, 99]


def test_out_of_range_is_an_index_error() -> None:
    with closing(Spool[int]()) as spool:
        spool.append(1)
        with pytest.raises(IndexError, match="out of range"):
            spool[1]
        with pytest.raises(IndexError):
            spool[-2]
