"""Adaptive rays (render/probes, issue 59): a probe whose irradiance is still noisy after the bake's
rays gets more. A corridor's deep probes are lit after several bounces from its open end: few of
their paths carry that light, so their mean over 1,024 rays moved 20-40% from seed to seed. After
the first pass each live probe's relative standard error is estimated (noise); those over
`probes.target_noise` trace as many rays again in fresh directions (rays.ray_directions' further
batches), and again, until they are under it or at `probes.max_rays`. A probe well over the target
(at it or above) then holds the equal-weight mean over all of its rays (combined_values): the same
as one pass over those directions. Between LOW and 1 times the target a round's mean is blended in
by a weight rising from 0 to 1 (ramp), so that a probe a hair either side of a threshold reads the
same: a hard threshold moved l_room's frame 8% between scales 1 and 100, whose float32 hits differ by
1e-4 and flipped the probes on its edge."""

from __future__ import annotations

import math

import numpy as np

from iblbake.core.metrics import luminance
from iblbake.render.probes.project import probe_values
from iblbake.render.probes.rays import ray_directions

BATCHES = 7         # interleaved sub-batches of a probe's rays whose spread estimates its noise; not a Fibonacci
                    # number: every 8th ray of a spherical Fibonacci set turns 8 golden angles, a whole turn
                    # less 0.056, and each batch was a narrow wedge of the sphere
DARK = 0.05         # directions whose irradiance is under this share of the probe's brightest are not judged
AXES = np.concatenate([np.eye(3), -np.eye(3)])          # the directions a probe's irradiance is judged at


def noise(radiance, t, dirs) -> np.ndarray:
    """(probes,) each probe's relative standard error: its irradiance's luminance at the six axis
    directions (the cosine-weighted mean of the rays that met no back face) over BATCHES
    interleaved sub-batches of its rays (ray i in batch i mod BATCHES, each spread over the
    sphere): the standard deviation of the part the rays that met the scene bring, over
    sqrt(BATCHES) and over the whole's mean; the largest over the
    directions with at least DARK of the probe's brightest; 0 for a probe all dark."""
    lum = luminance(radiance) * (t >= 0)                        # (probes, rays)
    cos = np.maximum(0.0, dirs[:, :3] @ AXES.T)                  # (rays, 6)
    batch = np.arange(len(dirs)) % BATCHES == np.arange(BATCHES)[:, None]       # (batches, rays)
    w = (batch[:, :, None] * cos[None]).transpose(1, 0, 2).reshape(len(dirs), -1)
    w = w / np.maximum(w.sum(0), 1e-300)
    mean = (lum @ w).reshape(len(lum), BATCHES, len(AXES)).mean(1)
    # the spread of the rays that met the scene: an escaping ray reads the sky filtered over its share
    # (no path noise), and a small bright light met by one batch's rays is not noise of the whole set
    hit = (lum * np.isfinite(t)) @ w
    se = hit.reshape(len(lum), BATCHES, len(AXES)).std(1, ddof=1) / math.sqrt(BATCHES)
    judged = (mean > 0) & (mean >= DARK * mean.max(1, keepdims=True))
    return np.where(judged, se / np.where(judged, mean, 1.0), 0.0).max(1)


LOW = 0.5           # of target_noise: a probe over it takes a round, blended in by ramp


def ramp(n, target: float) -> np.ndarray:
    """A round's weight for probes of noise n (before it): 0 under LOW x target, 1 from the target."""
    return np.clip((np.asarray(n, np.float64) / target - LOW) / (1.0 - LOW), 0.0, 1.0)


CAP = 8             # the most rays a noisy probe takes, omitted max_rays: this many times rays
RAY_BYTES = 64      # host memory a further ray takes: the trace's float32 results, the float64 copies kept and
                    # those its probe's combination concatenates


def ray_cap(settings: dict) -> int:
    """The most rays a probe takes: probes.max_rays (omitted: CAP x rays) rounded down to rays
    times a power of two (a noisy probe's rays double); rays where it is off (0, or target_noise 0)
    or under twice rays."""
    rays, most = settings["rays"], settings.get("max_rays")
    most = CAP * rays if most is None else most
    if not settings["target_noise"] or most < 2 * rays:
        return rays
    return rays << int(math.log2(most // rays))


def batch_directions(settings: dict, first: int, count: int) -> np.ndarray:
    """(count rays, 4) batches first .. first + count - 1 of the probes' directions, each ray's share
    of the sphere 4 pi / rays in w (an escaping ray reads the sky filtered as the first pass's do)."""
    rays, seed = settings["rays"], settings["seed"]
    dirs = np.concatenate([ray_directions(rays, seed, b) for b in range(first, first + count)])
    return np.concatenate([dirs, np.full((len(dirs), 1), 4 * np.pi / rays)], 1)


def more_rays(tracer, positions, live, radiance, t, settings: dict, progress=None):
    """(each probe's rays, the rounds) after the first pass (radiance, t of every probe over
    ray_directions(rays, seed)): while a live probe's noise is over LOW x target_noise (and every
    round before weighed it in) and twice its rays are within ray_cap, it traces as many rays again
    (with k batches so far: batches k .. 2k - 1, its rays numbered on from k x rays so that no ray's
    random stream repeats another's). A round is (the probes' indices, their radiance, their t, the
    weight its mean takes: the previous round's times ramp of the noise before it); a round whose
    rays would not fit in this process's memory is not traced (the third value: how many probes it
    left noisy, else 0)."""
    from iblbake.io import memory
    from iblbake.render.paths.trace import describe

    rays, cap, target = settings["rays"], ray_cap(settings), settings["target_noise"]
    counts = np.full(len(positions), rays)
    rounds = []
    todo = np.flatnonzero(live)
    weight = np.zeros(0)
    if cap > rays and len(todo):
        weight = ramp(noise(radiance[todo], t[todo], batch_directions(settings, 0, 1)), target)
        todo, weight = todo[weight > 0], weight[weight > 0]
    while len(todo) and 2 * counts[todo[0]] <= cap:
        k = counts[todo[0]] // rays                  # the batches each has: a round's probes have as many
        free = memory.host_bytes_available()
        if free is not None and len(todo) * 2 * k * rays * RAY_BYTES > free:
            return counts, rounds, len(todo)
        describe(progress, f"{len(todo):,} noisy probes x {k * rays} more rays")
        rad, tt, _ = tracer.trace(positions[todo], batch_directions(settings, k, k), True, ray0=k * rays)
        rounds.append((todo, rad, tt, weight))
        counts[todo] *= 2
        r, d, dirs = rays_of(todo, radiance, t, rounds, settings)
        weight = weight * ramp(noise(r, d, dirs), target)
        todo, weight = todo[weight > 0], weight[weight > 0]
    return counts, rounds, 0


def rays_of(idx, radiance, t, rounds, settings: dict):
    """(radiance, t, dirs) of all the rays of probes idx, each of which took part in every round
    given: the first pass's, then each round's, in the order of their directions."""
    rad, dist = [radiance[idx]], [t[idx]]
    for ids, r, d, _w in rounds:
        at = np.searchsorted(ids, idx)
        rad.append(r[at])
        dist.append(d[at])
    return np.concatenate(rad, 1), np.concatenate(dist, 1), batch_directions(settings, 0, 1 << len(rounds))


def combined_values(radiance, t, rounds, spacing, settings: dict):
    """probe_values of every probe: the first pass's, and for each round a probe took, its mean
    over the first pass's and the rounds' rays so far (one pass over those directions) blended in
    by the round's weight (1: that mean alone, what a probe over the target holds)."""
    dirs = batch_directions(settings, 0, 1)[:, :3]
    irr, moments = probe_values(radiance, t, dirs, spacing, settings)
    for k in range(1, len(rounds) + 1):
        idx, w = rounds[k - 1][0], rounds[k - 1][3]
        r, d, more = rays_of(idx, radiance, t, rounds[:k], settings)
        e, m = probe_values(r, d, more[:, :3], spacing, settings)
        for held, mean in ((irr, e), (moments, m)):      # each probe's own weight over its values' axes
            held[idx] += w.reshape((-1,) + (1,) * (mean.ndim - 1)) * (mean - held[idx])
    return irr, moments
