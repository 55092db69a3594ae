"""The floating-point range of a cast: scenes, cameras and rays scaled by powers of two.

The core's ray-triangle tests multiply up to three coordinate differences (Woop et al.'s
t numerator), so products overflow or underflow long before a coordinate does: a scene
1e-120 or 1e120 across would give t = 0 or inf. Scaling every length by a power of two is
exact (the same bits, shifted), so the core sees a scene about 1 across and rays whose
directions are about 1 long, and the lengths it returns (t, Depth, Position) are shifted
back. Where the answer would still leave the range, a ValueError names the limit.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

#: Scenes between 2**-SCENE_SAFE and 2**SCENE_SAFE across (2e-10 to 4e9), and directions
#: between 2**-SAFE and 2**SAFE long, are left unscaled: their outputs then need no pass
#: to shift them back, and the scene is built once.
SCENE_SAFE = 32
SAFE = 16
#: In the core's units, a ray origin or eye may be at most 2**LIMIT from the scene's
#: centre: the cube of that distance, times 2**SAFE for a direction's shear, stays
#: within the precision's range (float32 tests multiply float32 differences:
#: 2**(3 * 36 + 16) < 2**127).
LIMIT = {np.float64: 300, np.float32: 36}
#: Directions whose largest components lie within [SAFE_LONGEST[0], SAFE_LONGEST[1]) are
#: left unscaled (within 2**±SAFE).
SAFE_LONGEST = (math.ldexp(1.0, -SAFE - 1), math.ldexp(1.0, SAFE))


def exponent(x: float) -> int:
    """e with 2**(e - 1) <= |x| < 2**e (0 for 0)."""
    return math.frexp(x)[1]


class Scale(NamedTuple):
    """Lengths in the core are 2**shift times the user's; ``centre`` and ``size`` are the
    scene's box (user units), which the range limits are measured from; ``reach`` the
    centre's largest coordinate magnitude."""

    shift: int
    centre: np.ndarray
    size: float
    reach: float

    def check_origins(
        self, points: np.ndarray, real: type, what: str, *, extent: tuple[float, float] | None = None
    ) -> None:
        """Raises if a point (ray origin, eye) is too far from the scene for ``real``.
        ``extent``: the least and greatest coordinate of ``points``, when known."""
        if len(points) == 0:
            return
        if LIMIT[real] - self.shift >= 1024:  # beyond float64: every finite point is within it
            return
        limit = math.ldexp(1.0, LIMIT[real] - self.shift)
        if extent is None:  # (a bound first: one pass over contiguous memory is cheap)
            extent = float(points.min()), float(points.max())
        if max(-extent[0], extent[1]) + self.reach <= limit:
            return
        with np.errstate(over="ignore"):  # (an overflow is beyond every limit)
            far = max(float(np.abs(points[:, k] - self.centre[k]).max()) for k in range(3))
        if far > limit:
            raise ValueError(
                f"{what} lies {far:.3g} from the scene's centre, beyond the {limit:.3g} that "
                f"{np.dtype(real).name} casts support for a scene {self.size:.3g} across"
            )


def scene_scale(bounds) -> Scale:
    """The power of two that brings the box ``(xmin, xmax, ..., zmax)`` of the points the
    triangles use to about 1 across (none when it is between 2**-SCENE_SAFE and 2**SCENE_SAFE)."""
    low, high = np.asarray(bounds[0::2], float), np.asarray(bounds[1::2], float)
    if not (np.isfinite(low).all() and np.isfinite(high).all()):  # no triangles
        return Scale(0, np.zeros(3), 0.0, 0.0)
    half = float((high / 2 - low / 2).max())  # halves: the difference itself may overflow
    if half == 0:  # a single point: its magnitude is the only scale there is
        half = float(np.abs(high).max()) / 2
    size = 2 * half if half <= np.finfo(np.float64).max / 2 else math.inf
    centre = low / 2 + high / 2
    reach = float(np.abs(centre).max())
    if half == 0 or -SCENE_SAFE <= exponent(half) + 1 <= SCENE_SAFE:
        return Scale(0, centre, size, reach)
    return Scale(-(exponent(half) + 1), centre, size, reach)


def direction_shifts(
    directions: np.ndarray, bounded: bool, *, extent: tuple[float, float] | None = None
) -> int | np.ndarray:
    """Powers of two that bring each direction's largest component to [0.5, 1): per ray,
    or one for all when ``bounded`` (tmin, tmax are one pair for all rays), which then must
    not differ in length by more than 2**(2 SAFE). 0 when every direction is within
    2**±SAFE already. ``extent``: the least and greatest largest component, when known."""
    if extent is not None and SAFE_LONGEST[0] <= extent[0] and extent[1] < SAFE_LONGEST[1]:  # (the usual case, at once)
        return 0
    if len(directions) == 0:
        return 0
    longest = None
    if extent is None:
        longest = _longest(directions)
        extent = longest.min(), longest.max()
    high, low = exponent(float(extent[1])), exponent(float(extent[0]))
    if -SAFE <= low and high <= SAFE:
        return 0
    if longest is None:
        longest = _longest(directions)
    exponents = np.frexp(longest)[1]
    if not bounded:
        return -exponents
    if high - low > 2 * SAFE:
        raise ValueError(
            f"with tmin or tmax given, ray directions may differ in length by at most 2**{2 * SAFE} "
            f"(here 2**{high - low}); normalise them, or cast them in separate calls"
        )
    return -high


def _longest(directions: np.ndarray) -> np.ndarray:
    """Each direction's largest |component| (columns: cheaper than axis=1)."""
    longest = np.abs(directions[:, 0])
    np.maximum(longest, np.abs(directions[:, 1]), out=longest)
    np.maximum(longest, np.abs(directions[:, 2]), out=longest)
    return longest


def shift_lengths(values: np.ndarray, shift: int | np.ndarray, what: str, *, distance: bool = True) -> None:
    """Multiplies ``values`` by 2**-shift in place (exact), raising where a hit's value
    would leave the range of its type: an inf, or for a distance (t, Depth) a 0 or a
    subnormal that lost digits (a coordinate near 0 may be as small as it likes)."""
    if shift == 0 if isinstance(shift, int) else np.all(shift == 0):
        return
    hit = np.isfinite(values) & (values != 0)
    with np.errstate(over="ignore", under="ignore"):
        np.ldexp(values, -shift, out=values)
    size = np.abs(values[hit])
    smallest = np.finfo(values.dtype).tiny if distance else 0
    if not (np.isfinite(size) & (size >= smallest)).all():
        raise ValueError(
            f"a hit's {what} lies beyond the range of {values.dtype.name}; cast in float64 or rescale the rays"
        )
