"""Topic names, frame ids, schema names and metadata names of cldet's MCAP logs, defined once.

Every log written by ``cldet convert`` holds the sensor channels below (one per modality found
in the sequence); ``cldet annotate`` adds the result channels. Times on every channel are
integer nanoseconds since the Unix epoch: log time = publish time = the message's own
timestamp = the challenge file's stamp.
"""

from __future__ import annotations

from typing import Final

# --- sensor channels (written by `cldet convert`) ------------------------------------------
LIDAR_360: Final = "/lidar_360"  # foxglove.PointCloud, Livox Mid-360, valid points only
LIVOX_AVIA: Final = "/livox_avia"  # foxglove.PointCloud, Livox Avia, already in the Mid-360 frame
RADAR: Final = "/radar_enhance_pcl"  # foxglove.PointCloud, radar frame; empty frames kept
GROUND_TRUTH: Final = "/ground_truth"  # foxglove.PoseInFrame, Leica MS60 (train only)
CLASS: Final = "/class"  # cldet.ClassLabel, drone type 0..3 (train only)
IMAGE: Final = "/image"  # foxglove.CompressedImage, PNG, two fisheyes side by side
IMAGE_CALIBRATION: Final = "/image/calibration"  # foxglove.CameraCalibration for IMAGE
TF: Final = "/tf"  # foxglove.FrameTransforms: the static frame tree, once at the first stamp

# dataset folder name (converters.mmaud modality) -> topic
MODALITY_TOPICS: Final[dict[str, str]] = {
    "lidar_360": LIDAR_360,
    "livox_avia": LIVOX_AVIA,
    "radar_enhance_pcl": RADAR,
    "ground_truth": GROUND_TRUTH,
    "class": CLASS,
    "Image": IMAGE,
}
CLOUD_TOPICS: Final = (LIDAR_360, LIVOX_AVIA, RADAR)

# --- result channels (written by `cldet annotate`) -----------------------------------------
ESTIMATE: Final = "/cldet/estimate"  # cldet.Estimate, one per Mid-360 frame (refined track)
CAUSAL: Final = "/cldet/causal"  # cldet.Estimate, the causal estimate as it was made per frame
CLASS_ESTIMATE: Final = "/cldet/class"  # cldet.ClassEstimate, the drone type (with --model)
POSE: Final = "/cldet/pose"  # foxglove.PoseInFrame (Foxglove draws it; Rerun: see DRONE)
TRAJECTORY: Final = "/cldet/trajectory"  # foxglove.PosesInFrame, the track (Rerun: TRACK)
FOREGROUND: Final = "/cldet/foreground"  # foxglove.PointCloud x,y,z,cluster_id
CLUSTERS: Final = "/cldet/clusters"  # foxglove.SceneUpdate, cluster boxes + labels
# the same results as point clouds, which Rerun's MCAP import draws too (it draws PointCloud,
# not PoseInFrame, PosesInFrame or SceneUpdate); x,y,z float32 + red,green,blue,alpha uint8
DRONE: Final = "/cldet/drone"  # foxglove.PointCloud, 1 point per frame, coloured by source
TRACK: Final = "/cldet/track"  # foxglove.PointCloud, the whole refined track once (magenta)
TRUTH_TRACK: Final = "/cldet/truth_track"  # foxglove.PointCloud, the ground truth once (white)
CENTROIDS: Final = "/cldet/centroids"  # foxglove.PointCloud, cluster centres (chosen: green)
# channel metadata marking a channel as a result that the next annotate run replaces (for one
# outside /cldet/, e.g. the /tf annotate adds to a log that has none)
RESULT_CHANNEL_KEY: Final = "cldet.result"

# --- coordinate frames (one tree on /tf, see cldet.io.transforms) ----------------------------
FRAME_WORLD: Final = "world"  # level, z up, on the ground below the Mid-360: the tree's root
FRAME_MID360: Final = "mid360"  # the Mid-360's frame: metres, z up; both LiDARs and the GT
FRAME_RADAR: Final = "radar"  # the radar's own frame (z = boresight; approximate extrinsic)
FRAME_CAMERA: Final = "fisheye"  # the side-by-side fisheye image pair

MODALITY_FRAMES: Final[dict[str, str]] = {
    "lidar_360": FRAME_MID360,
    "livox_avia": FRAME_MID360,
    "radar_enhance_pcl": FRAME_RADAR,
    "ground_truth": FRAME_MID360,
    "Image": FRAME_CAMERA,
}

# --- schemas and encodings ---------------------------------------------------------------------
MESSAGE_ENCODING: Final = "protobuf"
SCHEMA_ENCODING: Final = "protobuf"
SCHEMA_POINT_CLOUD: Final = "foxglove.PointCloud"
POINT_TIME_FIELD: Final = "time"
"""A ``foxglove.PointCloud`` FLOAT32 field cldet writes after x, y, z where the source recorded
it: each point's firing time after the message's ``timestamp``, seconds (``Cloud.times``).
Viewers ignore it; ``cldet annotate`` dates the points by it."""
TIMED_CLOUD_FIELDS = ("x", "y", "z", POINT_TIME_FIELD)
SCHEMA_POSE_IN_FRAME: Final = "foxglove.PoseInFrame"
SCHEMA_POSES_IN_FRAME: Final = "foxglove.PosesInFrame"
SCHEMA_COMPRESSED_IMAGE: Final = "foxglove.CompressedImage"
SCHEMA_CAMERA_CALIBRATION: Final = "foxglove.CameraCalibration"
SCHEMA_SCENE_UPDATE: Final = "foxglove.SceneUpdate"
SCHEMA_FRAME_TRANSFORMS: Final = "foxglove.FrameTransforms"
SCHEMA_CLASS_LABEL: Final = "cldet.ClassLabel"
SCHEMA_ESTIMATE: Final = "cldet.Estimate"
SCHEMA_CLASS_ESTIMATE: Final = "cldet.ClassEstimate"

# --- metadata records ------------------------------------------------------------------------
METADATA_SOURCE: Final = "cldet.source"  # split, sequence, source path, counts, cldet version
METADATA_CONFIG: Final = "cldet.config"  # the effective configuration of an annotate run
