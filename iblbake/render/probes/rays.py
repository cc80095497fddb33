"""Probe rays (render/probes): their directions, RTXGI's spherical Fibonacci set randomly rotated
per bake, and the further sets a noisy probe gets (batch b > 0: the same set under another
rotation of the seed). The paths' Tracer (render/paths/tracer.py) traces them."""

from __future__ import annotations

import numpy as np


def spherical_fibonacci(n: int) -> np.ndarray:
    """n near-uniform directions (RTXGI's SphericalFibonacci: golden-ratio turns, equal-area rings)."""
    i = np.arange(n) + 0.5
    z = 1 - 2 * i / n
    phi = 2 * np.pi * np.mod(i * (np.sqrt(5) - 1) / 2, 1.0)
    r = np.sqrt(np.maximum(0, 1 - z * z))
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], -1)


def random_rotation(seed) -> np.ndarray:
    """A uniformly random rotation (Arvo 1992, Graphics Gems III: RTXGI's ComputeRandomRotation);
    seed an int or a sequence of them (numpy's SeedSequence)."""
    u1, u2, u3 = np.random.default_rng(seed).random(3)
    a, b = 2 * np.pi * u1, 2 * np.pi * u2
    rz = np.array([[np.cos(a), np.sin(a), 0], [-np.sin(a), np.cos(a), 0], [0, 0, 1]])
    v = np.array([np.cos(b) * np.sqrt(u3), np.sin(b) * np.sqrt(u3), np.sqrt(1 - u3)])
    return -(np.eye(3) - 2 * np.outer(v, v)) @ rz


def ray_directions(n: int, seed: int, batch: int = 0) -> np.ndarray:
    """A probe's n rays: batch 0 the bake's set, batch b > 0 the same set under the rotation of
    (seed, b), fresh directions for a noisy probe's further rays (render/probes/adaptive.py)."""
    return spherical_fibonacci(n) @ random_rotation(seed if batch == 0 else (seed, batch)).T
