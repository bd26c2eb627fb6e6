"""LeRobot's feature statistics: min, max, mean, std, count and the quantiles q01, q10, q50, q90,
q99.

Numeric features are reduced over frames (one value per component); images per colour channel in
[0, 1], shaped (3, 1, 1) as LeRobot keeps them. The quantiles here are exact (numpy's linear
interpolation), where LeRobot estimates them from histograms; the dataset's stats are computed over
all its frames, not merged from the episodes'.
"""

from __future__ import annotations

import numpy as np

QUANTILES = (0.01, 0.10, 0.50, 0.90, 0.99)
_Q_KEYS = tuple(f"q{round(q * 100):02d}" for q in QUANTILES)
IMAGE_SAMPLE_FRAMES = 100  # at most this many frames of an episode are looked at
IMAGE_SAMPLE_SIDE_PX = 150  # each subsampled to at most this many pixels along its longer side


def feature_stats(values: np.ndarray) -> dict[str, list]:
    """Statistics of a (frames,) or (frames, n) array, per component; min and max keep an integer
    feature's integers. Shapes follow LeRobot: (1,) for a scalar feature, (n,) for a vector."""
    data = values.reshape(values.shape[0], -1)
    as_float = data.astype(np.float64)
    out = {
        "min": data.min(axis=0).tolist(),
        "max": data.max(axis=0).tolist(),
        "mean": as_float.mean(axis=0).tolist(),
        "std": as_float.std(axis=0).tolist(),
        "count": [int(data.shape[0])],
    }
    for key, q in zip(_Q_KEYS, np.quantile(as_float, QUANTILES, axis=0), strict=True):
        out[key] = q.tolist()
    return out


def image_sample(count: int) -> range:
    """Which of an episode's `count` frames image_stats looks at: evenly spaced, at most
    IMAGE_SAMPLE_FRAMES."""
    return range(0, count, max(1, count // IMAGE_SAMPLE_FRAMES))[:IMAGE_SAMPLE_FRAMES]


def image_stride(shape: tuple[int, ...]) -> int:
    """The pixel stride that brings a frame's longer side to at most IMAGE_SAMPLE_SIDE_PX."""
    return -(-max(shape[:2]) // IMAGE_SAMPLE_SIDE_PX)  # ceil


def image_stats(frames: list[np.ndarray]) -> dict[str, list]:
    """Per-channel statistics of (H, W, 3) uint8 frames scaled to [0, 1], each shaped (3, 1, 1)."""
    sample = [frames[k] for k in image_sample(len(frames))]
    stride = image_stride(sample[0].shape)
    return sampled_image_stats([f[::stride, ::stride] for f in sample])


def sampled_image_stats(thumbs: list[np.ndarray]) -> dict[str, list]:
    """image_stats from the sampled frames already subsampled (image_sample, image_stride): what an
    export keeps of an episode's pictures while it streams them into the video."""
    pixels = np.concatenate([t.reshape(-1, 3) for t in thumbs]).astype(np.float64) / 255.0
    flat = feature_stats(pixels)
    return {
        key: value if key == "count" else [[[v]] for v in value]
        for key, value in {**flat, "count": [len(thumbs)]}.items()
    }
