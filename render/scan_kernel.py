"""The compiled per-frame kernel of the scanned head's drawing (render.scan_look.ScanRows): positions,
vertex normals and a fold-shadow term in one pass, in its own module so that importing the renderer
does not import numba (a render process of an export is handed the rows and never needs it)."""

from __future__ import annotations

import numba
import numpy as np
from sim.numba_start import prepare_blas_check

from render.normals_kernel import add_face_normal, face_cross, start_rows, unit_normals

prepare_blas_check()  # before this module's first kernel runs: see sim.numba_start

SNAP = 1.0 / 64.0  # pixels: slack for the rasterizer's rounding of a corner (it snaps to 1/256 px)


@numba.njit(cache=True, nogil=True)
def _fold(pos: np.ndarray, nbr_ptr: np.ndarray, nbr: np.ndarray, inv_len: np.ndarray, scratch: np.ndarray,
          out: np.ndarray, skip_v: np.ndarray, closed: bool) -> None:
    """out[:, 6]: the fold term of scan_rows, from the positions and the unit normals in out
    (left as it was at the vertices skip_v marks: bit 2 always, bit 1 when `closed`)."""
    n = pos.shape[0]
    mask = 3 if closed else 2
    for i in range(n):
        lo, hi = nbr_ptr[i], nbr_ptr[i + 1]
        if hi == lo or skip_v[i] & mask:
            scratch[i] = 0.0
            continue
        sx = np.float32(0.0)
        sy = np.float32(0.0)
        sz = np.float32(0.0)
        for k in range(lo, hi):
            j = nbr[k]
            sx += pos[j, 0]
            sy += pos[j, 1]
            sz += pos[j, 2]
        m = np.float32(1.0) / np.float32(hi - lo)
        dx, dy, dz = sx * m - pos[i, 0], sy * m - pos[i, 1], sz * m - pos[i, 2]
        scratch[i] = (dx * out[i, 3] + dy * out[i, 4] + dz * out[i, 5]) * inv_len[i]
    for i in range(n):
        if skip_v[i] & mask:
            continue
        lo, hi = nbr_ptr[i], nbr_ptr[i + 1]
        s = scratch[i]
        for k in range(lo, hi):
            s += scratch[nbr[k]]
        out[i, 6] = s / np.float32(1 + hi - lo)


@numba.njit(cache=True, nogil=True)
def openings(pos: np.ndarray, loop_ptr: np.ndarray, loops: np.ndarray, clip: np.ndarray, size: np.ndarray,
             margin: float, planes: np.ndarray, boxes: np.ndarray, hulls: np.ndarray, hull_n: np.ndarray,
             walls: np.ndarray, wall_n: np.ndarray, wall_margin: float) -> None:
    """For each opening h of the skin (the posed vertices loops[loop_ptr[h]:loop_ptr[h + 1]] around it,
    ordered so that their area vector points out of the head): planes[h] = (n, d), n the unit area
    vector and d the least n . x over the loop (a point with n . p < d lies behind every point of
    any surface spanning the loop's corners); boxes[h] = the loop's box on screen (normalised device
    x0, x1, y0, y1, widened by `margin` pixels of the picture `size`), or every point of the screen
    when a loop vertex is not in front of the camera (`clip`: projection @ view, row-major); and
    the loop's convex hull on screen as hull_n[h] lines (nx, ny, c) in pixels, hulls[h, :hull_n[h]],
    each pushed out by `margin` (a point with nx x + ny y > c lies beyond the hull), none (hull_n[h]
    = 0) when a loop vertex is not in front of the camera. A surface spanning the loop can lie
    within the loop's convex hull in space (a fan from its centroid), whose picture is the convex
    hull of the loop's corners on screen: a point behind the plane and beyond one of these lines
    is seen, if at all, through the skin, not through the opening. walls[h, :wall_n[h]]: the
    sides (wx, wy, wz, c) of the prism along the plane's normal over the loop's convex hull seen
    along that normal, each pushed out by `wall_margin` (a point with w . p > c lies outside the
    prism): the line along the normal through a point beyond a wall misses every surface spanning
    the loop within its convex hull (see seen_triangles' `sealed`)."""
    margin_x, margin_y = 2.0 * margin / size[0], 2.0 * margin / size[1]
    for h in range(loop_ptr.shape[0] - 1):
        lo, hi = loop_ptr[h], loop_ptr[h + 1]
        cx = cy = cz = 0.0
        for k in range(lo, hi):
            cx += pos[loops[k], 0]
            cy += pos[loops[k], 1]
            cz += pos[loops[k], 2]
        m = 1.0 / (hi - lo)
        cx, cy, cz = cx * m, cy * m, cz * m
        ax = ay = az = 0.0
        x0, x1, y0, y1 = np.inf, -np.inf, np.inf, -np.inf
        everywhere = False
        for k in range(lo, hi):
            a, b = loops[k], loops[lo + (k - lo + 1) % (hi - lo)]
            ux, uy, uz = pos[a, 0] - cx, pos[a, 1] - cy, pos[a, 2] - cz
            vx, vy, vz = pos[b, 0] - cx, pos[b, 1] - cy, pos[b, 2] - cz
            ax += uy * vz - uz * vy
            ay += uz * vx - ux * vz
            az += ux * vy - uy * vx
            px, py, pz = pos[a, 0], pos[a, 1], pos[a, 2]
            w = clip[3, 0] * px + clip[3, 1] * py + clip[3, 2] * pz + clip[3, 3]
            if w <= 1e-6:
                everywhere = True
            else:
                x = (clip[0, 0] * px + clip[0, 1] * py + clip[0, 2] * pz + clip[0, 3]) / w
                y = (clip[1, 0] * px + clip[1, 1] * py + clip[1, 2] * pz + clip[1, 3]) / w
                x0, x1, y0, y1 = min(x0, x), max(x1, x), min(y0, y), max(y1, y)
        inv = 1.0 / max(np.sqrt(ax * ax + ay * ay + az * az), 1e-12)
        ax, ay, az = ax * inv, ay * inv, az * inv
        d = np.inf
        for k in range(lo, hi):
            a = loops[k]
            d = min(d, ax * pos[a, 0] + ay * pos[a, 1] + az * pos[a, 2])
        planes[h, 0], planes[h, 1], planes[h, 2], planes[h, 3] = ax, ay, az, d
        if everywhere:
            x0, x1, y0, y1 = -np.inf, np.inf, -np.inf, np.inf
        boxes[h, 0], boxes[h, 1] = x0 - margin_x, x1 + margin_x
        boxes[h, 2], boxes[h, 3] = y0 - margin_y, y1 + margin_y
        hull_n[h] = 0 if everywhere else _hull(pos, loops[lo:hi], clip, size, margin, hulls[h])
        if walls.shape[0]:
            wall_n[h] = _walls(pos, loops[lo:hi], ax, ay, az, wall_margin, walls[h])


@numba.njit(cache=True, nogil=True)
def _walls(pos: np.ndarray, loop: np.ndarray, nx: float, ny: float, nz: float, margin: float,
           out: np.ndarray) -> int:
    """The sides of the prism along the unit vector n over the convex hull of the vertices `loop`
    seen along n, as planes (wx, wy, wz, c), w the unit outward normal, pushed out by `margin`;
    how many were written (0 when the hull is degenerate)."""
    if abs(nx) <= abs(ny) and abs(nx) <= abs(nz):  # u: n x the axis least along n
        ux, uy, uz = 0.0, nz, -ny
    elif abs(ny) <= abs(nz):
        ux, uy, uz = -nz, 0.0, nx
    else:
        ux, uy, uz = ny, -nx, 0.0
    inv = 1.0 / np.sqrt(ux * ux + uy * uy + uz * uz)
    ux, uy, uz = ux * inv, uy * inv, uz * inv
    vx, vy, vz = ny * uz - nz * uy, nz * ux - nx * uz, nx * uy - ny * ux
    n = loop.shape[0]
    pts = np.empty((n, 2))
    for k in range(n):
        px, py, pz = pos[loop[k], 0], pos[loop[k], 1], pos[loop[k], 2]
        pts[k, 0] = ux * px + uy * py + uz * pz
        pts[k, 1] = vx * px + vy * py + vz * pz
    lines = np.empty((n + 1, 3))
    m = _hull_lines(pts, margin, lines)
    for j in range(m):
        a, b = lines[j, 0], lines[j, 1]
        out[j, 0], out[j, 1], out[j, 2], out[j, 3] = a * ux + b * vx, a * uy + b * vy, a * uz + b * vz, lines[j, 2]
    return m


@numba.njit(cache=True, nogil=True)
def _hull(pos: np.ndarray, loop: np.ndarray, clip: np.ndarray, size: np.ndarray, margin: float,
          lines: np.ndarray) -> int:
    """The convex hull on screen (pixels) of the vertices `loop`, all in front of the camera, as
    lines (nx, ny, c): nx x + ny y = c along each edge pushed out by `margin`, (nx, ny) the unit
    outward normal; the number of lines written (0 when the hull is degenerate). Andrew's monotone
    chain (Inf. Proc. Letters 9, 1979)."""
    n = loop.shape[0]
    pts = np.empty((n, 2))
    for k in range(n):
        px, py, pz = pos[loop[k], 0], pos[loop[k], 1], pos[loop[k], 2]
        iw = 1.0 / (clip[3, 0] * px + clip[3, 1] * py + clip[3, 2] * pz + clip[3, 3])
        pts[k, 0] = ((clip[0, 0] * px + clip[0, 1] * py + clip[0, 2] * pz + clip[0, 3]) * iw + 1.0) * 0.5 * size[0]
        pts[k, 1] = ((clip[1, 0] * px + clip[1, 1] * py + clip[1, 2] * pz + clip[1, 3]) * iw + 1.0) * 0.5 * size[1]
    return _hull_lines(pts, margin, lines)


@numba.njit(cache=True, nogil=True)
def _hull_lines(pts: np.ndarray, margin: float, lines: np.ndarray) -> int:
    """The convex hull of the points `pts` (N, 2) as lines (nx, ny, c), each pushed out by
    `margin` (see `_hull`); how many were written. Andrew's monotone chain."""
    n = pts.shape[0]
    order = np.argsort(pts[:, 0])
    chain = np.empty(2 * n + 1, np.int64)
    m = 0
    for rnd in range(2):  # the lower hull left to right, then the upper right to left
        base = m
        for j in range(n):
            k = order[j] if rnd == 0 else order[n - 1 - j]
            while m >= base + 2:
                o, a = chain[m - 2], chain[m - 1]
                cross = ((pts[a, 0] - pts[o, 0]) * (pts[k, 1] - pts[o, 1])
                         - (pts[a, 1] - pts[o, 1]) * (pts[k, 0] - pts[o, 0]))
                if cross > 0.0:
                    break
                m -= 1
            chain[m] = k
            m += 1
        m -= 1  # each half's last point starts the other half
    if m < 3:
        return 0
    out = 0
    for j in range(m):  # counter-clockwise: the outside is on the right of each edge
        a, b = chain[j], chain[(j + 1) % m]
        dx, dy = pts[b, 0] - pts[a, 0], pts[b, 1] - pts[a, 1]
        length = np.sqrt(dx * dx + dy * dy)
        if length < 1e-9:
            continue
        nx, ny = dy / length, -dx / length
        lines[out, 0], lines[out, 1], lines[out, 2] = nx, ny, nx * pts[a, 0] + ny * pts[a, 1] + margin
        out += 1
    return out


@numba.njit(cache=True, nogil=True, inline="always")
def _beyond_hull(xy: np.ndarray, a: int, b: int, c: int, lines: np.ndarray, n: int) -> bool:
    """Whether the corners a b c (pixels, xy) all lie beyond one line of a hull (see `_hull`);
    False when a corner is not in front of the camera (NaN)."""
    for e in range(n):
        nx, ny, d = lines[e, 0], lines[e, 1], lines[e, 2]
        if (nx * xy[a, 0] + ny * xy[a, 1] > d and nx * xy[b, 0] + ny * xy[b, 1] > d
                and nx * xy[c, 0] + ny * xy[c, 1] > d):
            return True
    return False


@numba.njit(cache=True, nogil=True, inline="always")
def _beyond_walls(pos: np.ndarray, a: int, b: int, c: int, walls: np.ndarray, n: int) -> bool:
    """Whether the corners a b c all lie beyond one wall of a prism (see `_walls`)."""
    for e in range(n):
        wx, wy, wz, d = walls[e, 0], walls[e, 1], walls[e, 2], walls[e, 3]
        if (wx * pos[a, 0] + wy * pos[a, 1] + wz * pos[a, 2] > d
                and wx * pos[b, 0] + wy * pos[b, 1] + wz * pos[b, 2] > d
                and wx * pos[c, 0] + wy * pos[c, 1] + wz * pos[c, 2] > d):
            return True
    return False


@numba.njit(cache=True, nogil=True)
def _screen(pos: np.ndarray, clip: np.ndarray, size: np.ndarray, planes: np.ndarray, boxes: np.ndarray,
            inside: np.ndarray, xy: np.ndarray, code: np.ndarray, deep: np.ndarray) -> None:
    """xy: each vertex in pixels (x right, y up, the picture `size` wide and high; NaN for a vertex
    not in front of the camera); code, at the vertices `inside` marks: per opening h, four bits
    (left of, right of, below, above its box on screen) at bits 4h..4h+3, set where the vertex
    lies in front of the camera; deep: bit h where it lies behind h's plane too."""
    hx, hy = 0.5 * size[0], 0.5 * size[1]
    for i in range(pos.shape[0]):
        px, py, pz = pos[i, 0], pos[i, 1], pos[i, 2]
        w = clip[3, 0] * px + clip[3, 1] * py + clip[3, 2] * pz + clip[3, 3]
        c = 0
        e = 0
        if w > 1e-6:
            iw = 1.0 / w
            x = (clip[0, 0] * px + clip[0, 1] * py + clip[0, 2] * pz + clip[0, 3]) * iw
            y = (clip[1, 0] * px + clip[1, 1] * py + clip[1, 2] * pz + clip[1, 3]) * iw
            xy[i, 0] = (x + 1.0) * hx
            xy[i, 1] = (y + 1.0) * hy
            if not inside[i]:
                code[i] = 0
                deep[i] = 0
                continue
            for h in range(planes.shape[0]):
                bits = ((x < boxes[h, 0]) * 1 + (x > boxes[h, 1]) * 2 + (y < boxes[h, 2]) * 4
                        + (y > boxes[h, 3]) * 8)
                c |= bits << (4 * h)
                if planes[h, 0] * px + planes[h, 1] * py + planes[h, 2] * pz < planes[h, 3]:
                    e |= 1 << h
        else:
            xy[i, 0] = np.nan
            xy[i, 1] = np.nan
        code[i] = c
        deep[i] = e


@numba.njit(cache=True, nogil=True)
def screen_box(xy: np.ndarray, box: np.ndarray) -> None:
    """box = (x0, y0, x1, y1): the box on screen, in pixels (x right, y up), of every vertex of
    `xy` (as `_screen` left them); the whole plane when one is not in front of the camera (NaN).
    One pass without an early exit (a third quicker: 0.02 ms for the scan's 26,719 vertices)."""
    x0 = y0 = np.float32(np.inf)
    x1 = y1 = np.float32(-np.inf)
    bad = False
    for i in range(xy.shape[0]):
        x, y = xy[i, 0], xy[i, 1]
        bad |= (x != x) | (y != y)  # NaN: never taken by the comparisons below
        x0 = x if x < x0 else x0
        x1 = x if x > x1 else x1
        y0 = y if y < y0 else y0
        y1 = y if y > y1 else y1
    if bad:
        box[0], box[1], box[2], box[3] = -np.inf, -np.inf, np.inf, np.inf
    else:
        box[0], box[1], box[2], box[3] = x0, y0, x1, y1


@numba.njit(cache=True, nogil=True, inline="always")
def _turned_on_screen(xy: np.ndarray, a: int, b: int, c: int) -> int:
    """How the triangle a b c (corners in pixels, xy, y up) faces the camera on screen: 0 when it
    turns its back by more than its corners' rounding can undo, so that OpenGL's back-face culling
    (counter-clockwise is front) drops it: its doubled signed area below -SNAP times its perimeter
    (L1; a corner moving by SNAP moves the doubled area by at most that); 1 otherwise; -1 when a
    corner is not in front of the camera. Cheaper than the test in space, from the pixels the
    listing has."""
    ax, bx, cx = xy[a, 0], xy[b, 0], xy[c, 0]
    ay, by, cy = xy[a, 1], xy[b, 1], xy[c, 1]
    if np.isnan(ax) or np.isnan(bx) or np.isnan(cx):
        return -1
    ux, uy, vx, vy = bx - ax, by - ay, cx - ax, cy - ay
    area = ux * vy - uy * vx
    if area >= 0.0:
        return 1
    edges = abs(ux) + abs(uy) + abs(vx) + abs(vy) + abs(cx - bx) + abs(cy - by)
    return 0 if area < -SNAP * edges else 1


@numba.njit(cache=True, nogil=True, inline="always")
def _no_pixel(xy: np.ndarray, a: int, b: int, c: int, size: np.ndarray, small: float) -> bool:
    """Whether the triangle a b c (corners in pixels, xy) lies wholly off the picture, its box holds
    no pixel centre (k + 0.5), or (a box of at most `small` centres) none of those centres lies
    within SNAP pixels of it, so it can cover no pixel; False when a corner is not in front of the
    camera. SNAP pixels of slack cover the rasterizer's rounding of the corners (a point of the
    triangle moves by at most that when they move by that)."""
    ax, bx, cx = xy[a, 0], xy[b, 0], xy[c, 0]
    ay, by, cy = xy[a, 1], xy[b, 1], xy[c, 1]
    if np.isnan(ax) or np.isnan(bx) or np.isnan(cx):
        return False
    x0, x1 = min(ax, bx, cx) - SNAP, max(ax, bx, cx) + SNAP
    y0, y1 = min(ay, by, cy) - SNAP, max(ay, by, cy) + SNAP
    if x1 < 0.0 or y1 < 0.0 or x0 > size[0] or y0 > size[1]:
        return True
    i0, i1 = np.ceil(x0 - 0.5), np.floor(x1 - 0.5)
    j0, j1 = np.ceil(y0 - 0.5), np.floor(y1 - 0.5)
    if i1 < i0 or j1 < j0:
        return True
    if (i1 - i0 + 1.0) * (j1 - j0 + 1.0) > small:
        return False
    area = (bx - ax) * (cy - ay) - (by - ay) * (cx - ax)
    if abs(area) < 1e-12:
        return False  # no orientation to test against: kept
    s = 1.0 if area > 0.0 else -1.0
    # the centre nearest the triangle's centroid first: most small triangles hold it
    if _near_triangle(ax, ay, bx, by, cx, cy, s, np.floor((ax + bx + cx) / 3.0) + 0.5,
                      np.floor((ay + by + cy) / 3.0) + 0.5):
        return False
    j = j0
    while j <= j1:
        i = i0
        while i <= i1:
            if _near_triangle(ax, ay, bx, by, cx, cy, s, i + 0.5, j + 0.5):
                return False
            i += 1.0
        j += 1.0
    return True


@numba.njit(cache=True, nogil=True, inline="always")
def _edge_near(ux: float, uy: float, vx: float, vy: float, s: float, px: float, py: float) -> bool:
    """Whether (px, py) lies on the inner side of the edge u -> v (s: the triangle's orientation)
    or within SNAP of its line."""
    dx, dy = vx - ux, vy - uy
    e = s * (dx * (py - uy) - dy * (px - ux))
    return e >= 0.0 or e * e <= SNAP * SNAP * (dx * dx + dy * dy)


@numba.njit(cache=True, nogil=True, inline="always")
def _near_triangle(ax: float, ay: float, bx: float, by: float, cx: float, cy: float, s: float, px: float,
                   py: float) -> bool:
    """Whether the point (px, py) lies in the triangle a b c grown by SNAP along each edge."""
    return (_edge_near(bx, by, cx, cy, s, px, py) and _edge_near(cx, cy, ax, ay, s, px, py)
            and _edge_near(ax, ay, bx, by, s, px, py))


@numba.njit(cache=True, nogil=True)
def ball_sides(pos: np.ndarray, eye: np.ndarray, ball_idx: np.ndarray, ball_w: np.ndarray, ball_r: np.ndarray,
               near: np.ndarray, near_bits: np.ndarray, out: np.ndarray) -> None:
    """For each ball k (its centre the affine combination ball_w[k] of the posed vertices
    ball_idx[k], so it follows their rigid motion; radius ball_r[k]) and each vertex near[j] whose
    near_bits[j] holds bit k: out[near[j]] bit k set when the vertex lies in the ball, or within the
    ball's cone of sight from `eye` and beyond the plane of the circle where that cone touches the
    ball (left as it was at the other vertices). That region is convex (the ball and the cone
    behind the circle meet tangentially), and the line of sight to any point in it enters the ball
    first: a triangle whose corners all lie in it is hidden by any closed surface around the ball
    (an eyeball's outer shell, drawn)."""
    ex, ey, ez = float(eye[0]), float(eye[1]), float(eye[2])
    for j in range(near.shape[0]):
        out[near[j]] = 0
    for k in range(ball_idx.shape[0]):
        cx = cy = cz = 0.0
        for m in range(ball_idx.shape[1]):
            v = ball_idx[k, m]
            cx += ball_w[k, m] * pos[v, 0]
            cy += ball_w[k, m] * pos[v, 1]
            cz += ball_w[k, m] * pos[v, 2]
        r2 = ball_r[k] * ball_r[k]
        wx, wy, wz = cx - ex, cy - ey, cz - ez
        reach = wx * wx + wy * wy + wz * wz - r2  # the squared distance to the ball's tangent circle
        if reach <= 0.0:
            continue  # the eye in the ball: it hides nothing
        for j in range(near.shape[0]):
            if not (near_bits[j] >> k) & 1:
                continue
            i = near[j]
            qx, qy, qz = pos[i, 0], pos[i, 1], pos[i, 2]
            dx, dy, dz = qx - cx, qy - cy, qz - cz
            if dx * dx + dy * dy + dz * dz < r2:
                out[i] |= 1 << k
                continue
            vx, vy, vz = qx - ex, qy - ey, qz - ez
            t = vx * wx + vy * wy + vz * wz
            if t > reach and t * t >= (vx * vx + vy * vy + vz * vz) * reach:
                out[i] |= 1 << k


@numba.njit(cache=True, nogil=True)
def scan_rows(pos: np.ndarray, tri: np.ndarray, nbr_ptr: np.ndarray, nbr: np.ndarray, inv_len: np.ndarray,
              scratch: np.ndarray, out: np.ndarray, skip_tri: np.ndarray, skip_v: np.ndarray, closed: bool) -> None:
    """out[:, 0:3] = pos; out[:, 3:6] = unit area-weighted vertex normals; out[:, 6] = how far the
    vertex lies below the mean of its mesh neighbours, along its normal, per neighbour distance
    (`inv_len`: 1 / the rest's mean edge length there), averaged once more over the neighbours:
    positive in a crease (a fold, the nasolabial groove, the frown lines), negative on a ridge.
    It is recomputed from the posed surface every frame, so a fold that deepens darkens.

    The triangles skip_tri marks and the vertices skip_v marks are passed over: with bit 2 always
    (what no shader reads: the lashes' normals, the eyeballs' and lashes' fold terms), with bit 1
    when `closed` (the mouth's inside is not drawn; deep in the mouth: their normals and folds feed
    no drawn vertex). Their rows are left as they were."""
    start_rows(pos, out)
    mask = 3 if closed else 2
    for t in range(tri.shape[0]):
        if skip_tri[t] & mask:
            continue
        add_face_normal(pos, tri, t, out)
    unit_normals(out, pos.shape[0])
    _fold(pos, nbr_ptr, nbr, inv_len, scratch, out, skip_v, closed)


@numba.njit(cache=True, nogil=True)
def seen_triangles(pos: np.ndarray, tri: np.ndarray, skip_tri: np.ndarray, closed: bool, group: np.ndarray,
                   starts: np.ndarray, eye: np.ndarray, kept: np.ndarray, counts: np.ndarray,
                   behind: np.ndarray, clip: np.ndarray, size: np.ndarray, planes: np.ndarray,
                   boxes: np.ndarray, hulls: np.ndarray, hull_n: np.ndarray, inside: np.ndarray, xy: np.ndarray,
                   code: np.ndarray, deep: np.ndarray, ball_idx: np.ndarray, ball_w: np.ndarray, ball_r: np.ndarray,
                   near: np.ndarray, near_bits: np.ndarray, occluded: np.ndarray, sides: np.ndarray,
                   small: float, sealed: np.ndarray, walls: np.ndarray, wall_n: np.ndarray) -> None:
    """The triangles of each drawn group g (group[t] = g >= 0) that may be seen from `eye` (the
    camera's position, model space), listed in order at kept[starts[g]:starts[g] + counts[g]]
    (independent of scan_rows, so the two can run at once). A triangle is left out when the eye
    lies behind its plane by more than 1e-3 rad, or, given the picture and its corners in front of
    the camera, in place of that, when they turn clockwise on screen by more than their rounding
    can undo (`_turned_on_screen`: it costs less): OpenGL's back-face culling would drop it anyway. Given the camera's `clip` matrix (projection @ view, row-major; size[0] > 0, the
    picture's size in pixels), also when it covers no pixel (`_no_pixel`: off the picture, or too
    thin to hold a pixel centre; one whose box holds at most `small` centres is tested at each);
    a triangle inside the head (behind[t]: a bit per opening of the skin it can be seen through,
    render.scan_look; its corners marked in `inside`) when, for each of those openings (`planes`,
    `boxes`, `hulls`: see `openings`), it lies behind the opening and its three corners beyond one
    side of the opening's box on screen, or beyond one edge of the opening's convex hull there
    (the box first: it costs least): the line of sight to any of its points then passes through
    the skin, which is drawn; and a triangle that a ball can hide (occluded[t]: a bit per ball, see
    `ball_sides`; an eye socket behind its eyeball) when its three corners lie in that ball's
    hidden region. The picture is the same, and the rasterizer fetches and sets up only the rest.
    `xy`, `code` and `deep` are scratch for the corners' pixels, sides and the planes they lie
    behind, `sides` for the balls' bits at the vertices `near` lists (`near_bits`: the balls that
    may hide each). The deep mouth's triangles (skip_tri) are passed over when `closed`.
    sealed[t]: a bit per opening that the triangle never passes through (a tooth or gum, which stay
    behind the lips): for such an opening, in place of lying behind its plane, the triangle may lie
    beside it, its three corners beyond one wall of the opening's prism (`walls`, `wall_n`: see
    `openings`); the line along the opening's normal from any of its points then misses the
    opening's spanning surface and meets the skin, so it lies enclosed by skin and that surface as
    a triangle behind the opening does."""
    for g in range(counts.shape[0]):
        counts[g] = 0
    view = size[0] > 0
    if view:
        _screen(pos, clip, size, planes, boxes, inside, xy, code, deep)
        if ball_idx.shape[0]:
            ball_sides(pos, eye, ball_idx, ball_w, ball_r, near, near_bits, sides)
    ex, ey, ez = np.float32(eye[0]), np.float32(eye[1]), np.float32(eye[2])
    hair = np.float32(1e-6)  # (1e-3)^2: compared with squares, no square root per triangle
    for t in range(tri.shape[0]):
        g = group[t]
        if g < 0 or (closed and skip_tri[t]):
            continue
        a, b, c = tri[t, 0], tri[t, 1], tri[t, 2]
        on_screen = _turned_on_screen(xy, a, b, c) if view else -1
        if on_screen == 0:
            continue
        if on_screen < 0:  # a corner not in front of the camera, or no picture: the test in space
            cx, cy, cz = face_cross(pos, a, b, c)
            wx, wy, wz = ex - pos[a, 0], ey - pos[a, 1], ez - pos[a, 2]
            d = cx * wx + cy * wy + cz * wz
            if d < 0 and d * d > hair * (cx * cx + cy * cy + cz * cz) * (wx * wx + wy * wy + wz * wz):
                continue
        if view:
            if _no_pixel(xy, a, b, c, size, small):
                continue
            if occluded[t] & sides[a] & sides[b] & sides[c]:
                continue
            if behind[t] and planes.shape[0]:
                side = code[a] & code[b] & code[c]
                under = deep[a] & deep[b] & deep[c]
                hidden = True
                for h in range(planes.shape[0]):
                    if not (behind[t] >> h) & 1:
                        continue
                    if not ((under >> h) & 1 or ((sealed[t] >> h) & 1
                                                 and _beyond_walls(pos, a, b, c, walls[h], wall_n[h]))):
                        hidden = False
                        break
                    if (side >> (4 * h)) & 15 == 0 and not _beyond_hull(xy, a, b, c, hulls[h], hull_n[h]):
                        hidden = False
                        break
                if hidden:
                    continue
        k = starts[g] + counts[g]
        kept[k, 0] = a
        kept[k, 1] = b
        kept[k, 2] = c
        counts[g] += 1
