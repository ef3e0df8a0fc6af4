"""Seat the eyeballs of an imported head behind its own lid openings, the way a resting face shows
its eyes: the upper lid covers the top of the iris by a millimetre or two, the lower lid touches its
bottom, the iris sits in the middle of the opening, and the lids rest on the eyeball.

Carried through the skin correspondence, an eyeball lands where the reference face had it, which on
a head of other proportions can be in front of the lids (the ball bulges through the opening), to
one side of it, or under a lid. And a head's own lids (or lids parted from a scan's shut ones) may
open wider than a resting face's: with white all round the iris the face reads as startled. So,
from the head's own geometry alone, each eye's opening is brought to the height a resting face
has for an iris of the eyeball's size, and the eyeball is placed behind it."""

from __future__ import annotations

import dataclasses

import numpy as np

from sim.model import FaceMesh
from sim.face.transfer.lids import set_gap

FloatArray = np.ndarray
IntArray = np.ndarray

# The iris of the drawn eye is the cap within this angle of the gaze (render/shaders.py EYE_FS puts
# its edge at 0.50-0.54 rad): its radius is about half the eyeball's, 6 mm on a 12 mm eyeball.
IRIS_ANGLE = 0.52
COVER_TOP = 0.2  # of the eyeball's radius: the upper lid hides ~2 mm of the iris' top at rest
COVER_BOTTOM = 0.05  # the lower lid just covers the iris' bottom rim
CLEARANCE = 0.04  # of the radius: the lid margins lie this far outside the eyeball
UP = np.array([0.0, 1.0, 0.0])
FORWARD = np.array([0.0, 0.0, 1.0])


@dataclasses.dataclass(frozen=True)
class EyeSeat:
    """What seating one eye did: the opening's height at the middle before and after (cm)."""

    gap_before: float
    gap_after: float


def iris_radius(eye_radius: float) -> float:
    """Radius (cm) of the drawn iris seen from the front, for an eyeball of `eye_radius`."""
    return float(eye_radius * np.sin(IRIS_ANGLE))


def rest_gap(eye_radius: float) -> float:
    """The opening's height at the middle (cm) of a resting eye of this size: the iris' height less
    what the lids cover of it."""
    return 2.0 * iris_radius(eye_radius) - (COVER_TOP + COVER_BOTTOM) * eye_radius


def lid_chains(vertices: FloatArray, loop: IntArray, inner: FloatArray, outer: FloatArray) -> tuple[IntArray, IntArray]:
    """(upper, lower) lid margins of an eye's loop, each from the inner corner to the outer: the
    loop is split at its vertices nearest the two corner landmarks; the higher half is the upper."""
    loop = np.asarray(loop, dtype=np.int64)
    p = vertices[loop]
    i = int(np.argmin(np.linalg.norm(p - inner, axis=1)))
    j = int(np.argmin(np.linalg.norm(p - outer, axis=1)))
    n = len(loop)
    one = loop[[(i + k) % n for k in range((j - i) % n + 1)]]
    other = loop[[(i - k) % n for k in range((i - j) % n + 1)]]
    if vertices[one[1:-1], 1].mean() >= vertices[other[1:-1], 1].mean():
        return one, other
    return other, one


def _point(vertices: FloatArray, chain: IntArray, a: FloatArray, axis: FloatArray, t: float) -> FloatArray:
    """The chain's point (3,) at fraction `t` between the corners (interpolated along the axis)."""
    p = vertices[chain]
    tc = (p - a) @ axis / (axis @ axis)
    order = np.argsort(tc)
    return np.array([np.interp(t, tc[order], p[order, k]) for k in range(3)])


def seat_eye(vertices: FloatArray, loop: IntArray, inner: FloatArray, outer: FloatArray,
             eye_radius: float) -> tuple[FloatArray, FloatArray, EyeSeat]:
    """(vertices with the opening at `rest_gap`, the eyeball's centre, what was done) for one eye.

    The lids are moved by `lids.set_gap` (the upper lid most, the skin around following). The
    centre lies under the middle of the opening, at the height that puts the iris' bottom on the
    lower lid, and as far forward as it can with every lid vertex in front of the ball (at least
    CLEARANCE x radius outside it): the lids rest on the eyeball. Vertices deeper than the lid
    margins (a socket, or an eye surface modelled behind the opening) do not push it back."""
    upper, lower = lid_chains(vertices, loop, inner, outer)
    a, b = vertices[upper[0]], vertices[upper[-1]]
    axis = b - a
    up = UP - (UP @ axis) * axis / (axis @ axis)
    up /= np.linalg.norm(up)
    before = float((_point(vertices, upper, a, axis, 0.5) - _point(vertices, lower, a, axis, 0.5)) @ up)
    v = set_gap(vertices, upper, lower, rest_gap(eye_radius), UP)
    top, bottom = _point(v, upper, a, axis, 0.5), _point(v, lower, a, axis, 0.5)
    after = float((top - bottom) @ up)
    r_iris = iris_radius(eye_radius)
    mid = a + 0.5 * axis
    base = mid + up * (float((bottom - mid) @ up) + r_iris - COVER_BOTTOM * eye_radius)
    forward = FORWARD - (FORWARD @ up) * up
    forward /= np.linalg.norm(forward)
    # every vertex of the lids (within the eyeball's reach across the gaze, and no deeper than the
    # lid margins: a socket or an eye's own surface modelled behind the opening is not a lid) must
    # lie outside the ball: the farthest forward the centre may go
    q = v - base
    along = q @ forward
    across2 = np.einsum("ij,ij->i", q, q) - along ** 2
    reach = (eye_radius * (1.0 + CLEARANCE)) ** 2 - across2
    margin = float(along[np.r_[upper, lower]].min())
    lids = (reach > 0) & (along >= margin - 1e-9)
    depth = float(np.min(along[lids] - np.sqrt(reach[lids]))) if lids.any() else -eye_radius
    centre = base + depth * forward
    return v, centre, EyeSeat(before, after)


def seat_eyes(mesh: FaceMesh) -> tuple[FaceMesh, list[str]]:
    """The mesh with both eyes seated (`seat_eye`), and a note for the report per eye."""
    v = np.asarray(mesh.vertices, float)
    centres = np.asarray(mesh.eye_centers, float).copy()
    notes = []
    for k, s in enumerate("lr"):
        inner, outer = mesh.landmark(f"eye_inner_{s}"), mesh.landmark(f"eye_outer_{s}")
        v, c, seat = seat_eye(v, mesh.eye_loops[k], inner, outer, float(mesh.eye_radius))
        moved = float(np.linalg.norm(c - centres[k]))
        centres[k] = c
        notes.append(f"eye_{s}: the opening set to a resting eye's {seat.gap_after:.2f} cm (was "
                     f"{seat.gap_before:.2f}); the eyeball seated behind it ({moved:.2f} cm from where "
                     "the correspondence put it)")
    return dataclasses.replace(mesh, vertices=v, eye_centers=centres), notes

