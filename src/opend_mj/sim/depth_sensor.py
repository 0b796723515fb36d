"""A real depth camera's image from a rendered one (the `depth_noise` perturbation axis, and training
data for solvers that must read a real sensor: `sensor_depth`).

The model (`DepthNoise`): axial noise sigma(z) = scale * (1.2 mm + 1.9 mm * (z - 0.4 m)^2) (a
structured-light sensor's, Nguyen et al. 2012); missing pixels (depth 0, as real sensors report them)
at depth edges, on near-black surfaces and at random. Several frames of a still scene are fused as a
depth camera's temporal filter fuses them (`fuse_depth`).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class DepthNoise:
    """The numbers of one sensor: noise scale and the chance that a pixel is missing."""

    #: axial noise sigma(z) = sigma_scale * (1.2 mm + 1.9 mm * (z - 0.4 m)^2)
    sigma_scale: float
    #: missing (depth 0) where the depth jumps by more than 3 cm to a neighbour, with this chance
    edge_dropout: float
    #: missing on near-black surfaces (grey below 30 of 255), with this chance
    dark_dropout: float
    #: missing anywhere, with this chance
    random_dropout: float


#: The two levels of the depth_noise axis (`sim.perturb`), by name.
DEPTH_NOISE_LEVELS = {
    "mild": DepthNoise(sigma_scale=1.0, edge_dropout=0.3, dark_dropout=0.3, random_dropout=0.005),
    "strong": DepthNoise(sigma_scale=3.0, edge_dropout=0.8, dark_dropout=0.7, random_dropout=0.02),
}


class DepthSensor:
    """A real depth camera's image from a rendered one: axial noise growing with distance, missing
    pixels (depth 0, as real sensors report them) at depth edges, on dark surfaces and at random.
    Deterministic: the k-th image of a scene gets the k-th draw of its seed (`count`; the task sets it
    back to 0 at each episode's start)."""

    def __init__(self, noise: DepthNoise, seed: int):
        self.noise = noise
        self.seed = int(seed)
        self.count = 0

    def __call__(self, rgb: np.ndarray, depth: np.ndarray) -> np.ndarray:
        lv = self.noise
        rng = np.random.default_rng([self.seed, self.count])
        self.count += 1
        z = np.asarray(depth, np.float32)
        valid = np.isfinite(z) & (z > 0)
        sigma = lv.sigma_scale * (0.0012 + 0.0019 * (np.where(valid, z, 0.4) - 0.4) ** 2)
        out = (z + rng.normal(size=z.shape) * sigma).astype(np.float32)
        jump = np.zeros(z.shape, bool)
        dz = np.abs(np.diff(z, axis=1)) > 0.03
        jump[:, 1:] |= dz
        jump[:, :-1] |= dz
        dz = np.abs(np.diff(z, axis=0)) > 0.03
        jump[1:, :] |= dz
        jump[:-1, :] |= dz
        grey = np.asarray(rgb, np.float32).mean(axis=-1) if rgb is not None else np.full(z.shape, 255.0)
        dark = grey < 30.0  # near-black surfaces return too little of the projector's light
        u = rng.uniform(size=z.shape)
        missing = ((jump & (u < lv.edge_dropout)) | (dark & (u < lv.dark_dropout))
                   | (rng.uniform(size=z.shape) < lv.random_dropout))
        out[missing | ~valid] = 0.0
        out[~valid] = z[~valid]
        return out


def sensor_depth(rgb: np.ndarray, depth: np.ndarray, level: "DepthNoise | str", seed: int,
                 frames: int = 1) -> np.ndarray:
    """A rendered depth image as the depth_noise sensor at ``level`` (a `DepthNoise`, or "mild" /
    "strong": `DEPTH_NOISE_LEVELS`) gives it, ``frames`` frames of the still scene fused as the task
    fuses them (`OpenCabinetTask.sense_depth`): training data for solvers that must read a real sensor."""
    noise = DEPTH_NOISE_LEVELS[level] if isinstance(level, str) else level
    sensor = DepthSensor(noise, seed)
    return fuse_depth([sensor(rgb, depth) for _ in range(max(1, int(frames)))])


def fuse_depth(frames: list[np.ndarray]) -> np.ndarray:
    """One depth image from several frames of a still scene, as a depth camera's temporal filter
    gives it: per pixel, the median of the frames that have a reading (0, none, where no frame has
    one). Independent noise shrinks about as 1/sqrt(frames); a pixel missing in some frames is filled.
    One frame, or identical frames, come back unchanged."""
    if len(frames) == 1:
        return frames[0]
    stack = np.stack([np.asarray(f, np.float32) for f in frames])
    read = np.isfinite(stack) & (stack > 0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # "All-NaN slice": no frame read that pixel
        fused = np.nanmedian(np.where(read, stack, np.nan), axis=0)
    return np.where(read.any(axis=0), fused, stack[0]).astype(np.float32)
