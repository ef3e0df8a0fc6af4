"""Seat the eyeballs of an imported head behind its own lid openings, the way a resting face shows
its eyes: the upper lid covers the top of the iris by a millimetre or two, the lower lid touches its
bottom, the iris sits in the middle of the opening, and the lids rest on the eyeball.

Carried through the skin correspondence, an eyeball lands where the reference face had it, which on
a head of other proportions can be in front of the lids (the ball bulges through the opening), to
one side of it, or under a lid. And a head's own lids (or lids parted from a scan's shut ones) may
open wider than a resting face's: with white all round the iris the face reads as startled. So,
from the head's own geometry alone, each eye's opening as seen from the front is brought to the
height a resting face has for an iris of the eyeball's size (an eyeball too small for the opening
the head shows is grown first), and the eyeball is placed behind it."""

from __future__ import annotations

import dataclasses

import numpy as np

from sim.model import FaceMesh
from sim.face.transfer.lids import UPPER_SHARE, lid_sides, set_gap

FloatArray = np.ndarray
IntArray = np.ndarray

# The iris of the drawn eye is the cap within this angle of the gaze (render/shaders.py EYE_FS puts
# its edge at 0.50-0.54 rad): its radius is about half the eyeball's, 6 mm on a 12 mm eyeball.
IRIS_ANGLE = 0.52
COVER_TOP = 0.2  # of the eyeball's radius: the upper lid hides ~2 mm of the iris' top at rest
COVER_BOTTOM = 0.05  # the lower lid just covers the iris' bottom rim
CLEARANCE = 0.04  # of the radius: the lid margins lie this far outside the eyeball
SEEN_TOLERANCE = 0.01  # of the radius: an opening seen within this of its target is left as it is
MAX_OPENING = 2.0  # of a resting eye's opening: the rims part at most this much further to open it
UP = np.array([0.0, 1.0, 0.0])
FORWARD = np.array([0.0, 0.0, 1.0])


@dataclasses.dataclass(frozen=True)
class EyeSeat:
    """What seating one eye did: the opening's height at the middle before and after (cm)."""

    gap_before: float
    gap_after: float
    uncovered: str = ""  # how skin covering the opening was moved off it ("" when none had to be)


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


def mesh_lids(mesh: FaceMesh, k: int) -> tuple[IntArray, IntArray]:
    """(upper, lower) lid margins of the mesh's eye `k` (0 left, 1 right) at rest, each from the
    inner corner to the outer: its eye loop split at the corner landmarks (`lid_chains`)."""
    s = "lr"[k]
    return lid_chains(np.asarray(mesh.vertices, np.float64), mesh.eye_loops[k], mesh.landmark(f"eye_inner_{s}"),
                      mesh.landmark(f"eye_outer_{s}"))


def margin_point(vertices: FloatArray, chain: IntArray, a: FloatArray, axis: FloatArray, t: float) -> FloatArray:
    """The chain's point (3,) at fraction `t` between the corners (interpolated along the axis)."""
    p = vertices[chain]
    tc = (p - a) @ axis / (axis @ axis)
    order = np.argsort(tc)
    return np.array([np.interp(t, tc[order], p[order, k]) for k in range(3)])


def _along_margin(v: FloatArray, chain: IntArray, a: FloatArray, axis: FloatArray, t: FloatArray,
                  value: FloatArray) -> FloatArray:
    """(N,) a per-vertex `value` of a lid margin's chain, read at each vertex's fraction `t` between
    the corners (clipped to them), interpolated along the corners' axis."""
    tc = (v[chain] - a) @ axis / (axis @ axis)
    order = np.argsort(tc)
    return np.interp(np.clip(t, 0.0, 1.0), tc[order], value[chain][order])


def _not_behind(v: FloatArray, upper: IntArray, lower: IntArray, forward: FloatArray) -> np.ndarray:
    """(N,) bool: the vertices no deeper along `forward` than the lid margins between the corners
    at their place (the shallower of the two chains there; beyond the corners, than the deepest
    margin). What lies behind the margins inside the opening is not a lid seen from the front: a
    socket, an eye surface modelled behind the opening, or the halves of a shut lid's back layer
    stretched between the margins when a lid cut along its front is parted."""
    a, b = v[upper[0]], v[upper[-1]]
    axis = b - a
    t = (v - a) @ axis / (axis @ axis)
    d = (v - a) @ forward
    rim = np.minimum(_along_margin(v, upper, a, axis, t, d), _along_margin(v, lower, a, axis, t, d))
    deepest = float(d[np.r_[upper, lower]].min())
    return np.where((t > 0.0) & (t < 1.0), d >= rim - 1e-9, d >= deepest - 1e-9)


def covering_sheet(vertices: FloatArray, upper: IntArray, lower: IntArray) -> np.ndarray:
    """(N,) bool: the skin between the corners lying in front of the lid margins there, the skin
    that can hang over an eye's opening. A scan's shut lid can hang a sheet of one lid in front of
    the other's margin (the lower lid pushed up over a screwed-shut upper one, an upper lid blinked
    past the lower): beyond the other lid's margin such skin followed its own lid less the further
    it lay (`lids.set_gap`), so it stayed over the opening however far the lids parted."""
    v = np.asarray(vertices, float)
    a, b = v[upper[0]], v[upper[-1]]
    axis = b - a
    up = UP - (UP @ axis) * axis / (axis @ axis)
    up /= np.linalg.norm(up)
    forward = FORWARD - (FORWARD @ up) * up - (FORWARD @ axis) * axis / (axis @ axis)
    forward /= np.linalg.norm(forward)
    t = (v - a) @ axis / (axis @ axis)
    return (t > 0.0) & (t < 1.0) & _not_behind(v, upper, lower, forward)


def _within_opening(v: FloatArray, upper: IntArray, lower: IntArray, forward: FloatArray) -> np.ndarray:
    """(N,) bool: the vertices that a view along `forward` finds between the corners and between
    the two lid margins (the opening's outline seen from the front)."""
    a, b = v[upper[0]], v[upper[-1]]
    axis = b - a
    up = np.cross(forward, axis)
    up /= np.linalg.norm(up)
    t = (v - a) @ axis / (axis @ axis)
    h = (v - a) @ up
    top, bottom = _along_margin(v, upper, a, axis, t, h), _along_margin(v, lower, a, axis, t, h)
    return (t > 0.0) & (t < 1.0) & (h > np.minimum(top, bottom)) & (h < np.maximum(top, bottom))


def seen_opening(vertices: FloatArray, triangles: IntArray, upper: IntArray, lower: IntArray,
                 t: float = 0.5) -> tuple[float, float]:
    """(top, bottom) heights (cm, along the eye's up from its inner corner) of the opening one sees
    from the front at fraction `t` between the corners: the gap in the skin that a view along the
    face's forward axis finds around the middle of the rims there. The rims (the opening's loop,
    where a lid meets the eyeball or was cut) can lie behind and beyond the edge one sees: a thick
    lid's margin rolls in towards the eyeball and its front hangs over it, and the halves of a shut
    lid parted at rest fold over the opening. Skin deeper than the lid margins (a socket, an eye
    surface modelled behind the opening) is not seen through the eyeball and is left out: a
    triangle counts only when none of its corners lies behind them. (A triangle counted when one
    corner lay in front: the back layer of a lid shut in the file, stretched from a margin across
    the opening when the lids part, then read as the lower lid, and the shut-lidded development
    head's eye was parted 1.8 cm with the iris high over a grey wedge.) A shut opening gives
    top == bottom, at the rims' middle."""
    v = np.asarray(vertices, float)
    upper, lower = np.asarray(upper, dtype=np.int64), np.asarray(lower, dtype=np.int64)
    a, b = v[upper[0]], v[upper[-1]]
    axis = b - a
    width = float(np.linalg.norm(axis))
    side = axis / width
    up = UP - (UP @ side) * side
    up /= np.linalg.norm(up)
    forward = FORWARD - (FORWARD @ up) * up - (FORWARD @ side) * side  # the same on either eye
    forward /= np.linalg.norm(forward)
    q = v - a
    s, h, d = q @ side, q @ up, q @ forward
    x = t * width
    top = float((margin_point(v, upper, a, axis, t) - a) @ up)
    bottom = float((margin_point(v, lower, a, axis, t) - a) @ up)
    centre = 0.5 * (top + bottom)
    tri = np.asarray(triangles, dtype=np.int64)
    ts, th = s[tri], h[tri]
    # triangles the column crosses, near the eye, not behind the lid margins
    front = _not_behind(v, upper, lower, forward)
    keep = ((ts.min(axis=1) <= x) & (ts.max(axis=1) >= x) & (np.abs(th - centre).min(axis=1) < width)
            & front[tri].all(axis=1))
    ts, th = ts[keep], th[keep]
    lo = np.full(len(ts), np.inf)
    hi = np.full(len(ts), -np.inf)
    for i, j in ((0, 1), (1, 2), (2, 0)):
        si, sj, hi_, hj = ts[:, i], ts[:, j], th[:, i], th[:, j]
        cross = (np.minimum(si, sj) <= x) & (np.maximum(si, sj) >= x) & (si != sj)
        f = np.where(cross, (x - si) / np.where(si != sj, sj - si, 1.0), 0.0)
        y = hi_ + f * (hj - hi_)
        lo = np.where(cross, np.minimum(lo, y), lo)
        hi = np.where(cross, np.maximum(hi, y), hi)
    ok = lo <= hi
    lo, hi = lo[ok], hi[ok]
    if np.any((lo <= centre) & (hi >= centre)):
        return centre, centre
    seen_top = float(np.min(lo[lo > centre], initial=top))
    seen_bottom = float(np.max(hi[hi < centre], initial=bottom))
    return seen_top, seen_bottom


def seat_eye(vertices: FloatArray, triangles: IntArray, loop: IntArray, inner: FloatArray,
             outer: FloatArray, eye_radius: float) -> tuple[FloatArray, FloatArray, EyeSeat]:
    """(vertices with the opening seen from the front set for a resting eye, the eyeball's centre,
    what was done) for one eye.

    The opening is the one seen from the front (`seen_opening`), not the rims' gap: a thick lid
    hangs over its rim, and the halves of a lid shut in the file (parted by `lids.open_lids`) can
    still cover the opening. What is seen is brought to a resting eye's opening (`rest_gap`):
    neither a slit nor wider (a startled look must come from the lids moving, not from the rest
    shape). The lids are moved by `lids.set_gap` (the upper lid most, each vertex following its
    own lid along the skin, `lids.lid_sides`), the rims' gap found by bisection on what is seen;
    when skin bridging the lids still covers the opening with the rims MAX_OPENING x `rest_gap`
    further apart, the lids are left as they are. The centre lies
    under the middle of the opening, at the height that puts the iris' bottom on the lower lid as
    seen, and as far forward as it can with every lid vertex in front of the ball (at least
    CLEARANCE x radius outside it): the lids rest on the eyeball. Vertices deeper than the lid
    margins (a socket, or an eye surface modelled behind the opening) do not push it back."""
    upper, lower = lid_chains(vertices, loop, inner, outer)
    a, b = vertices[upper[0]], vertices[upper[-1]]
    axis = b - a
    up = UP - (UP @ axis) * axis / (axis @ axis)
    up /= np.linalg.norm(up)
    top, bottom = seen_opening(vertices, triangles, upper, lower)
    before = top - bottom
    rest = rest_gap(eye_radius)
    target = rest
    rims = float((margin_point(vertices, upper, a, axis, 0.5) - margin_point(vertices, lower, a, axis, 0.5)) @ up)
    v = np.asarray(vertices, float)
    uncovered = ""
    if abs(before - target) > SEEN_TOLERANCE * eye_radius:
        widest = rims + MAX_OPENING * rest
        sheet = covering_sheet(v, upper, lower)
        sides, whole, share = lid_sides(vertices, triangles, upper, lower), None, UPPER_SHARE
        uncovered = ""

        def seen(gap: float) -> float:
            return _seen_gap(set_gap(vertices, upper, lower, gap, UP, upper_share=share, upper_side=sides,
                                     whole=whole), triangles, upper, lower)

        # skin still covering the opening with the rims at their widest: first skin torn between
        # the lids (ties) goes up; then a sheet of one lid hanging in front beyond the other's
        # margin follows its lid whole (each, then both); then the lower lid takes more of the
        # parting (a lower lid pushed up in front of the upper one must go down for the eye to show)
        for ties, whole_, share_ in ((True, None, UPPER_SHARE), (False, sheet, UPPER_SHARE), (True, sheet, UPPER_SHARE),
                                     (False, sheet, 0.5), (True, sheet, 0.5), (False, sheet, 1.0 - UPPER_SHARE),
                                     (True, sheet, 1.0 - UPPER_SHARE), (None, sheet, UPPER_SHARE)):
            if seen(widest) >= target:
                break
            uncovered = _uncovering(ties, whole_ is not None, share_)
            sides = None if ties is None else lid_sides(vertices, triangles, upper, lower, ties_upper=ties)
            whole, share = whole_, share_
        lo, hi = 0.0, max(rims, target)
        while seen(hi) < target and hi < widest:
            lo, hi = hi, min(2.0 * hi, widest)
        if seen(hi) >= target:  # else skin bridging the lids covers the opening however far they part
            for _ in range(30):
                if hi - lo < 1e-4:
                    break
                g = 0.5 * (lo + hi)
                lo, hi = (g, hi) if seen(g) < target else (lo, g)
            v = set_gap(vertices, upper, lower, hi, UP, upper_share=share, upper_side=sides, whole=whole)
        else:
            uncovered = "none: skin bridging the lids covers the opening however far they part"
    top, bottom = seen_opening(v, triangles, upper, lower)
    after = top - bottom
    r_iris = iris_radius(eye_radius)
    mid = a + 0.5 * axis
    base = mid + up * (bottom + r_iris - COVER_BOTTOM * eye_radius)
    forward = FORWARD - (FORWARD @ up) * up
    forward /= np.linalg.norm(forward)
    # every vertex of the lids (within the eyeball's reach across the gaze, and no deeper than the
    # lid margins: a socket or an eye's own surface modelled behind the opening is not a lid) must
    # lie outside the ball: the farthest forward the centre may go
    q = v - base
    along = q @ forward
    across2 = np.einsum("ij,ij->i", q, q) - along ** 2
    reach = (eye_radius * (1.0 + CLEARANCE)) ** 2 - across2
    lids = (reach > 0) & _not_behind(v, upper, lower, forward)
    depth = float(np.min(along[lids] - np.sqrt(reach[lids]))) if lids.any() else -eye_radius
    centre = base + depth * forward
    v = tuck_back_layer(v, upper, lower, centre, eye_radius, forward)
    return v, centre, EyeSeat(before, after, uncovered)


def _uncovering(ties: bool | None, whole: bool, share: float) -> str:
    """The report's words for how the seat moved skin off a covered opening."""
    parts = ["the lids told apart by height" if ties is None else
             "skin torn between the lids given to the upper lid" if ties else "",
             "the sheet of a lid hanging over it moved whole with its lid" if whole else "",
             f"the upper lid taking {share:.0%} of the parting" if share != UPPER_SHARE else ""]
    return ", ".join(p for p in parts if p)


def tuck_back_layer(vertices: FloatArray, upper: IntArray, lower: IntArray, centre: FloatArray,
                    eye_radius: float, forward: FloatArray) -> FloatArray:
    """The vertices with the skin lying behind the lid margins but in front of the seated eyeball
    moved behind it. That skin is the back layer of a lid shut in the file (or a membrane closing
    its eye), stretched across the opening when the lids part: drawn in front of the eyeball it
    covered part of the eye with a grey wedge. In a living eye the lid's back surface runs from
    the margin round the eyeball into the socket, so each such vertex goes straight back, along
    the forward axis, to just behind the eyeball's back (CLEARANCE x radius outside it), where
    the eyeball hides it; skin already inside the eyeball stays."""
    v = np.asarray(vertices, float).copy()
    r = eye_radius * (1.0 + CLEARANCE)
    q = v - centre
    along = q @ forward
    across2 = np.einsum("ij,ij->i", q, q) - along ** 2
    column = across2 < r ** 2
    back = -np.sqrt(np.where(column, r ** 2 - across2, 0.0))
    outside = np.einsum("ij,ij->i", q, q) > eye_radius ** 2
    tuck = column & outside & (along > back) & _within_opening(v, upper, lower, forward) \
        & ~_not_behind(v, upper, lower, forward)
    v[tuck] += ((back - along)[tuck])[:, None] * forward
    return v


def _seen_gap(vertices: FloatArray, triangles: IntArray, upper: IntArray, lower: IntArray) -> float:
    top, bottom = seen_opening(vertices, triangles, upper, lower)
    return top - bottom


def eye_size(vertices: FloatArray, triangles: IntArray, mesh: FaceMesh, radius: float) -> float:
    """The eyeball's radius (cm) for this head: the carried `radius`, unless its iris is shorter
    than the opening the head shows from the front (both eyes' mean): then no seat can show the
    head's own eye (the lids brought to the small iris' resting opening made a thick-lidded
    scan's eyes slits, and left open they show white above or below the iris, a startled look),
    and the eyeball is the one whose resting opening (`rest_gap`) is the head's own. The scanned
    head's identity imported as skin alone: its carried eyeball 0.86 cm, its iris 0.86 cm tall in
    an opening seen 0.99 cm tall; grown to 1.33 cm (the scan's own eyeball is 1.38)."""
    seen = []
    for k, s in enumerate("lr"):
        upper, lower = lid_chains(vertices, mesh.eye_loops[k], mesh.landmark(f"eye_inner_{s}"),
                                  mesh.landmark(f"eye_outer_{s}"))
        top, bottom = seen_opening(vertices, triangles, upper, lower)
        seen.append(top - bottom)
    own = float(np.mean(seen))
    if 2.0 * iris_radius(radius) >= own:
        return radius
    return own / rest_gap(1.0)


def seat_eyes(mesh: FaceMesh) -> tuple[FaceMesh, list[str]]:
    """The mesh with both eyes seated (`seat_eye`) with an eyeball of `eye_size`, and a note for
    the report per eye."""
    v = np.asarray(mesh.vertices, float)
    centres = np.asarray(mesh.eye_centers, float).copy()
    notes = []
    radius = eye_size(v, mesh.triangles, mesh, float(mesh.eye_radius))
    for k, s in enumerate("lr"):
        inner, outer = mesh.landmark(f"eye_inner_{s}"), mesh.landmark(f"eye_outer_{s}")
        v, c, seat = seat_eye(v, mesh.triangles, mesh.eye_loops[k], inner, outer, radius)
        moved = float(np.linalg.norm(c - centres[k]))
        centres[k] = c
        if k == 0 and radius != float(mesh.eye_radius):
            notes.append(f"eyes: the eyeballs' radius {radius:.2f} cm, to fit the openings the head shows "
                         f"(carried: {float(mesh.eye_radius):.2f} cm, whose iris is shorter than them)")
        notes.append(f"eye_{s}: the opening seen from the front {seat.gap_after:.2f} cm (was "
                     f"{seat.gap_before:.2f}); the eyeball seated behind it ({moved:.2f} cm from where "
                     "the correspondence put it)" + (f"; skin covering the opening: {seat.uncovered}"
                                                    if seat.uncovered else ""))
    return dataclasses.replace(mesh, vertices=v, eye_centers=centres, eye_radius=radius), notes

