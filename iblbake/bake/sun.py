"""The panorama's sun as a light (`environment.sun: extract`).

A panorama has a sun when its brightest texel is PEAK times its median luminance or more, or
when the region about that texel (below) is compact and holds SUN_SHARE of the panorama's
energy or more: the sun is the connected region (8-neighbours, wrapping in azimuth) of texels
brighter than THRESHOLD times the median that holds the brightest texel, if it is compact (a
disk of at most MAX_DIAMETER degrees: a softbox or a bright sky patch is not a sun). The share's
rule takes a sun that a camera's filtering, haze or foliage spread below PEAK: what shading gets
wrong by leaving a sun in the panorama (a probe's shadowless sky, a prefiltered lobe through a
window's edge) scales with the sun's energy, not its peak. Its texels are
replaced by the level of its surroundings (the mean of the ring of texels around it, RING
texels wide), and exactly the removed energy comes back as a directional light: illuminance per
channel E_c = sum over the region of (L_c - fill_c) dOmega (what a surface facing the sun
receives from it, to the cosine spread over the disk: 1 - cos of half a degree is 4e-5), the
direction the removed energy's centroid, the angular diameter that of a disk of the region's
solid angle. A panorama with no texel above the threshold has no sun: nothing is extracted.

Blender's eight, peak / median luminance, the brightest region's diameter and share of the
energy: city 6e4, 1.5 degrees, 24%; interior 1e5, 1.6, 13%; sunrise 3e5, 4.4, 60%; night 3e5
(a lamp), 4.1, 17%: suns by their peak. forest 9e3, 2.7 degrees, 6.3%: a sun by its share (a
sun through foliage, 11% of the light on a plane facing it in the open and more through a
window, which cuts the sky, not the sun: 23% of what a gold sphere's lobe saw, its highlight
x0.83-0.85 of the truth while the sun stayed in the panorama, x0.96-1.02 extracted). sunset
7e3, 1.0 degrees, 2.3%: no sun (a setting sun the atmosphere dims to 4.8% of the light on a
plane facing it: its missing shadow within a probe's own error). courtyard 1e3, 8.0 degrees,
1.3% (an overcast sky's brightest patch, wider than any sun) and studio 2e4, 14 degrees (a
softbox): none. SUN_SHARE 0.04 sits between forest's and sunset's shares (1.6x and 0.6x).

extract_lights(image, count): the same for up to `count` regions, brightest first: the sun, and
lamps and softboxes up to LAMP_DIAMETER degrees carrying at least LAMP_SHARE of the panorama's
energy each (studio's four lamps, 4-16 degrees wide, 87% of its energy), each above PEAK (the
share's rule is the sun's: forest's second region, 6.6 degrees and 5% under 2e3 x median, is
bright sky). Each comes back as a directional light whose disk spreads its shadow's penumbra
(`sun_shadows: soft`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from iblbake.core import conventions
from iblbake.core.metrics import LUMINANCE

# Blender's panoramas (the module's docstring): city, interior, sunrise, night over PEAK; forest's
# sun under it (9e3) holds 6.3% of the energy, sunset's 2.3%, courtyard's brightest patch 8 degrees
PEAK = 1e4
SUN_SHARE = 0.04         # of the panorama's energy: a compact region holding this is a sun under PEAK
THRESHOLD = 100.0
MAX_DIAMETER = 6.0       # degrees (the sun's 0.53 spreads over 1.5-4.4 in a 1024x512 panorama)
RING = 2
MAX_TEXELS = 1 << 16     # the region search stops here (a bright sky, not a disk)
LAMP_DIAMETER = 20.0     # degrees: extract_lights takes lamps this wide (studio's span 4-16)
LAMP_SHARE = 0.02        # of the panorama's energy: a dimmer region stays in the panorama


@dataclass
class Sun:
    direction: list          # unit, from the scene towards the sun (the panorama's frame)
    color: list              # linear RGB, luminance 1: illuminance x color = E per channel
    illuminance: float       # luminance-weighted E (lux for a panorama in nits)
    angular_diameter: float  # degrees
    texels: int
    energy_fraction: float   # of the panorama's luminance x solid angle

    def to_json(self) -> dict:
        return {"direction": [round(x, 6) for x in self.direction], "color": [round(x, 6) for x in self.color],
                "illuminance": float(self.illuminance), "angular_diameter_deg": round(self.angular_diameter, 4),
                "texels": self.texels, "energy_fraction": round(self.energy_fraction, 6)}


def _region(mask: np.ndarray, seed: tuple) -> np.ndarray:
    """The 8-connected component of mask holding seed, wrapping in azimuth (columns)."""
    h, w = mask.shape
    out = np.zeros_like(mask)
    stack = [seed]
    out[seed] = True
    while stack:
        r, c = stack.pop()
        for dr in (-1, 0, 1):
            rr = r + dr
            if rr < 0 or rr >= h:
                continue
            for dc in (-1, 0, 1):
                cc = (c + dc) % w
                if mask[rr, cc] and not out[rr, cc]:
                    out[rr, cc] = True
                    stack.append((rr, cc))
        if len(stack) > MAX_TEXELS:
            break
    return out


def _dilate(region: np.ndarray, k: int) -> np.ndarray:
    out = region.copy()
    for _ in range(k):
        grown = out.copy()
        grown[1:] |= out[:-1]
        grown[:-1] |= out[1:]
        grown |= np.roll(out, 1, axis=1) | np.roll(out, -1, axis=1)
        out = grown
    return out


def _removed(img, region, om, total):
    """The region's texels down to its ring's level: (residual texels, Sun)."""
    n = int(region.sum())
    solid = float(om[region].sum())
    half = math.acos(max(-1.0, 1.0 - solid / (2 * math.pi)))
    ring = _dilate(region, RING) & ~region
    fill = img[ring].mean(axis=0)
    removed = np.maximum(img[region] - fill, 0.0)           # per texel and channel
    e = (removed * om[region][:, None]).sum(axis=0)           # E per channel, facing the sun
    h, w = img.shape[:2]
    dirs = conventions.equirect_texel_dirs(w, h)[region]
    centroid = ((removed @ LUMINANCE)[:, None] * om[region][:, None] * dirs).sum(axis=0)
    direction = centroid / np.linalg.norm(centroid)
    illum = float(e @ LUMINANCE)
    sun = Sun(direction=direction.tolist(), color=(e / illum).tolist() if illum > 0 else [1.0, 1.0, 1.0],
              illuminance=illum, angular_diameter=math.degrees(2 * half), texels=n,
              energy_fraction=float((removed @ LUMINANCE * om[region]).sum()) / total if total > 0 else 0.0)
    return np.minimum(img[region], fill), sun                 # never brighter than it was


def extract_lights(image, count: int = 1, max_diameter: float = MAX_DIAMETER, share: float = 0.0):
    """(residual panorama, [Sun]): up to count compact regions (at most max_diameter degrees, at
    least share of the energy), brightest texel first; the first (the sun) peaks at PEAK x median
    or holds SUN_SHARE of the energy within MAX_DIAMETER degrees, the rest peak at PEAK x median."""
    img = np.asarray(image, np.float64)[..., :3]
    h, w = img.shape[:2]
    lum = img @ LUMINANCE
    median = float(np.median(lum))
    om = conventions.equirect_solid_angles(w, h)
    total = float((lum * om).sum())
    bright = lum > THRESHOLD * median
    residual, found = img.copy(), []
    while len(found) < count and bright.any():
        peak = np.unravel_index(int(np.argmax(np.where(bright, lum, -np.inf))), lum.shape)
        if lum[peak] <= 0:
            break
        peaked = lum[peak] >= PEAK * max(median, 0.0)
        if not peaked and found:
            break                    # lamps peak over PEAK; only the sun may qualify by its share
        region = _region(bright, peak)
        bright &= ~region
        solid = float(om[region].sum())
        diameter = math.degrees(2 * math.acos(max(-1.0, 1.0 - solid / (2 * math.pi))))
        energy = float((lum * om)[region].sum())
        if not peaked and (int(region.sum()) > MAX_TEXELS or diameter > MAX_DIAMETER or energy < SUN_SHARE * total):
            break                    # under PEAK and not a compact region holding SUN_SHARE: no sun
        if int(region.sum()) > MAX_TEXELS or diameter > max_diameter:
            if count == 1:
                break                # the brightest region is no sun: the panorama has none
            continue
        if energy < share * total:
            continue
        residual[region], sun = _removed(img, region, om, total)
        found.append(sun)
    if not found:
        return np.asarray(image, np.float32), []
    return residual.astype(np.float32), found


def extract(image) -> tuple[np.ndarray, Sun | None]:
    """(residual panorama, Sun or None). The image is (H, W, 3) linear RGB."""
    residual, found = extract_lights(image, 1)
    return residual, (found[0] if found else None)
