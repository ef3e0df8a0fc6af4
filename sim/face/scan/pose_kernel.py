"""The scanned head's posing (`ScanDressing.pose`) as one compiled pass: the same steps in the same
order as the numpy version it replaces (copy the rest, the skin, the lips' inside, the vertices
bound to skin triangles, the lid things on the eyes' margins, the followers, the jaw's rigid
followers, the mouth socket, the eyes), without its temporaries: ~0.3 ms for the 26,719 vertices instead of ~2 ms, once per drawn frame.
Only what is drawn or exported is posed here; the simulation never reads it."""

from __future__ import annotations

import math

import numba
import numpy as np

from sim.numba_start import prepare_blas_check

prepare_blas_check()  # before this module's first kernel runs: see sim.numba_start


@numba.njit(cache=True, nogil=True)
def pose_scan(rest, x, skin, lip_idx, lip_anchor, lip_rot, bound_idx, bound_tri, bound_bary, bound_local,  # type: ignore[no-untyped-def]
              lid_idx, lid_margin, lid_t, lid_eye, lid_local, lid_open, lid_centres, lid_rest_n,
              follow_idx, follow_src, follow_w, jaw_idx, jaw_w, socket_idx, socket_anchor, socket_fade,
              rot, shift, tongue_idx, tongue_w, tongue, reach, narrow, eye_l, eye_r, centres, eye_rot, turn_eyes,
              d, buf, out):
    """out (26719,3) float32: the scan posed by the simulated surface x (N,3) with the jaw's motion
    p -> rot p + shift, the tongue out by `tongue` (0..1: its vertices move by their share of
    `reach` and narrow by `narrow` of their sideways offset) and, if turn_eyes, the eyeballs turned by eye_rot (2,3,3: left, right) about their centres.
    The lid things hang from the eyes' margins (`ScanDressing` lid_*; lid_centres (2,3) the
    eyeballs' centres; lid_rest_n (D,2,3) their closing and opening frames' normals at rest, the
    opening frame's kept: `dressing._lid_frames`). d (N,3) and buf (26719,3) are float64 scratch."""
    n = rest.shape[0]
    for i in range(n):
        for c in range(3):
            buf[i, c] = rest[i, c]
    for k in range(skin.shape[0]):
        s = skin[k]
        for c in range(3):
            buf[s, c] = x[k, c]
            d[k, c] = x[k, c] - rest[s, c]
    for k in range(lip_idx.shape[0]):  # the anchor's motion, turned with the jaw about the anchor
        i = lip_idx[k]
        a = lip_anchor[k]
        s = skin[a]
        q0 = rest[i, 0] - rest[s, 0]
        q1 = rest[i, 1] - rest[s, 1]
        q2 = rest[i, 2] - rest[s, 2]
        for c in range(3):
            t = (rot[c, 0] - (1.0 if c == 0 else 0.0)) * q0 + (rot[c, 1] - (1.0 if c == 1 else 0.0)) * q1 \
                + (rot[c, 2] - (1.0 if c == 2 else 0.0)) * q2
            buf[i, c] = rest[i, c] + d[a, c] + lip_rot[k] * t
    for k in range(bound_idx.shape[0]):  # in the frame (t1, t2, n) of a skin triangle
        i0, i1, i2 = bound_tri[k, 0], bound_tri[k, 1], bound_tri[k, 2]
        e1x, e1y, e1z = x[i1, 0] - x[i0, 0], x[i1, 1] - x[i0, 1], x[i1, 2] - x[i0, 2]
        e2x, e2y, e2z = x[i2, 0] - x[i0, 0], x[i2, 1] - x[i0, 1], x[i2, 2] - x[i0, 2]
        nx, ny, nz = e1y * e2z - e1z * e2y, e1z * e2x - e1x * e2z, e1x * e2y - e1y * e2x
        ln = math.sqrt(nx * nx + ny * ny + nz * nz)
        nx, ny, nz = nx / ln, ny / ln, nz / ln
        l1 = math.sqrt(e1x * e1x + e1y * e1y + e1z * e1z)
        tx, ty, tz = e1x / l1, e1y / l1, e1z / l1
        bx, by, bz = ny * tz - nz * ty, nz * tx - nx * tz, nx * ty - ny * tx
        w0, w1, w2 = bound_bary[k, 0], bound_bary[k, 1], bound_bary[k, 2]
        u0, u1, u2 = bound_local[k, 0], bound_local[k, 1], bound_local[k, 2]
        i = bound_idx[k]
        buf[i, 0] = w0 * x[i0, 0] + w1 * x[i1, 0] + w2 * x[i2, 0] + u0 * tx + u1 * bx + u2 * nx
        buf[i, 1] = w0 * x[i0, 1] + w1 * x[i1, 1] + w2 * x[i2, 1] + u0 * ty + u1 * by + u2 * ny
        buf[i, 2] = w0 * x[i0, 2] + w1 * x[i1, 2] + w2 * x[i2, 2] + u0 * tz + u1 * bz + u2 * nz
    for k in range(lid_idx.shape[0]):  # hanging from a margin segment, closing and opening frames blended
        i0, i1 = lid_margin[k, 0], lid_margin[k, 1]
        w = lid_t[k]
        ex, ey, ez = x[i1, 0] - x[i0, 0], x[i1, 1] - x[i0, 1], x[i1, 2] - x[i0, 2]
        fx, fy, fz = x[i0, 0] + w * ex, x[i0, 1] + w * ey, x[i0, 2] + w * ez
        e = lid_eye[k]
        s = 0.0  # the margin's motion away from the opening, over LID_OPEN: 0 closing .. 1 opening
        for c in range(3):
            s += (d[i0, c] + w * (d[i1, c] - d[i0, c])) * lid_open[k, c]
        s = min(max(s, 0.0), 1.0)
        s = s * s * (3.0 - 2.0 * s)
        p0 = 0.0
        p1 = 0.0
        p2 = 0.0
        for f in range(2):
            share = 1.0 - s if f == 0 else s
            if share == 0.0:  # wholly in the other frame
                continue
            if f == 0:  # about the eyeball's centre
                nx, ny, nz = fx - lid_centres[e, 0], fy - lid_centres[e, 1], fz - lid_centres[e, 2]
                ln = math.sqrt(nx * nx + ny * ny + nz * nz)
                nx, ny, nz = nx / ln, ny / ln, nz / ln
            else:  # the lid's surface at rest, turning with the margin's segment only
                nx, ny, nz = lid_rest_n[k, 1, 0], lid_rest_n[k, 1, 1], lid_rest_n[k, 1, 2]
            dot = ex * nx + ey * ny + ez * nz
            tx, ty, tz = ex - dot * nx, ey - dot * ny, ez - dot * nz
            lt = math.sqrt(tx * tx + ty * ty + tz * tz)
            tx, ty, tz = tx / lt, ty / lt, tz / lt
            bx, by, bz = ny * tz - nz * ty, nz * tx - nx * tz, nx * ty - ny * tx
            u0, u1, u2 = lid_local[k, f, 0], lid_local[k, f, 1], lid_local[k, f, 2]
            p0 += share * (u0 * tx + u1 * bx + u2 * nx)
            p1 += share * (u0 * ty + u1 * by + u2 * ny)
            p2 += share * (u0 * tz + u1 * bz + u2 * nz)
        i = lid_idx[k]
        buf[i, 0] = fx + p0
        buf[i, 1] = fy + p1
        buf[i, 2] = fz + p2
    for k in range(follow_idx.shape[0]):  # the skin's nearest vertices' displacement, fading
        i = follow_idx[k]
        for c in range(3):
            acc = 0.0
            for j in range(follow_src.shape[1]):
                acc += follow_w[k, j] * d[follow_src[k, j], c]
            buf[i, c] += acc
    for k in range(jaw_idx.shape[0]):  # the jaw's rigid followers
        i = jaw_idx[k]
        p0, p1, p2 = rest[i, 0], rest[i, 1], rest[i, 2]
        w = jaw_w[k]
        for c in range(3):
            moved = rot[c, 0] * p0 + rot[c, 1] * p1 + rot[c, 2] * p2 + shift[c]
            buf[i, c] = rest[i, c] + w * (moved - rest[i, c])
    if tongue:  # out between the lips, narrowing
        for k in range(tongue_idx.shape[0]):
            i = tongue_idx[k]
            w = tongue * tongue_w[k]
            for c in range(3):
                buf[i, c] += w * reach[c]
            buf[i, 0] -= w * narrow * rest[i, 0]
    for k in range(socket_idx.shape[0]):  # the mouth socket: the jaw's share, near the lips the lips'
        i = socket_idx[k]
        a = socket_anchor[k]
        f = socket_fade[k]
        for c in range(3):
            buf[i, c] = rest[i, c] + f * (buf[a, c] - rest[a, c]) + (1.0 - f) * (buf[i, c] - rest[i, c])
    if turn_eyes:
        for e in range(2):
            idx = eye_l if e == 0 else eye_r
            for k in range(idx.shape[0]):
                i = idx[k]
                q0 = rest[i, 0] - centres[e, 0]
                q1 = rest[i, 1] - centres[e, 1]
                q2 = rest[i, 2] - centres[e, 2]
                for c in range(3):
                    buf[i, c] = eye_rot[e, c, 0] * q0 + eye_rot[e, c, 1] * q1 + eye_rot[e, c, 2] * q2 + centres[e, c]
    for i in range(n):
        for c in range(3):
            out[i, c] = np.float32(buf[i, c])
