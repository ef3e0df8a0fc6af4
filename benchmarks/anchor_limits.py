"""How far the skin's tether anchors moving with the muscles could bring the scanned face to the scans (run by hand).

Every scanned ARKit shape (left and right apart, `scan_match.scan_targets`) is driven with the
channels the shipped ARKit map gives it (`shape_channels`) and settled on the shipped rig, as
`scan_match.py --no-fit` does. On top of that settled pose, each muscle channel gets a field of
tether-anchor displacements over its zone (`sim.face.scan.anchor_fit`: the deep tissue the muscle
lies in carrying the places the skin is tied to, scaled by the channel's value, the sides
mirrored), fitted in the linear statics of the shipped skin to what the settled pose misses, one
field per channel shared by every shape that drives it, on the left and unsided shapes; the right
ones are held out. Prints per shape the settled relative error (0 = the scan, 1 = as wrong as not
moving) and the linear model's prediction with the fitted fields.

`--halves` fits the sided halves' fields alone (`sim.channels.HALVES`: the lips' sphincter and
the mentalis per side) on the shapes that drive them, every other channel's anchors kept: each half
starts from its whole channel's field weighted by the side's share
(`sim.face.scan.anchor_fit.half_anchors`) and the fit adds to it; with `--write-rig` the rig keeps
every other field. The shipped halves: `--halves --all --smooth 1e-4 --bound 10 --grow 1.5
--write-rig sim/face/scan/ict_rig.npz` on the current rig (the halves restart from their wholes' fields, so
it rewrites the shipped rig byte for byte). `--only NAME[=GROW],...` (also spelt `--channels`)
refits the named channels' fields the same way, added to the rig's own: a channel's name, or a
muscle's base name for both its sides, each zone grown by its own GROW cm (`--grow` where none is
given), fitted on the shapes that drive them ("The inner brows and the cheek's squint"):

    # the shipped rig, the halves and the upper face's two fields each run once on the rig before
    nice .venv/bin/python benchmarks/anchor_limits.py --all --only frontalis_inner=1.5,orbicularis_oculi=5
        --smooth 1e-4 --bound 10 --write-rig sim/face/scan/ict_rig.npz
    nice .venv/bin/python benchmarks/anchor_limits.py --halves --all --smooth 1e-4 --bound 10 --grow 1.5
        --write-rig sim/face/scan/ict_rig.npz
    # the tissue under the pursed lips (docs/scan-face.md, "The tissue under the lips refitted"), on
    # the rig the commands before made
    nice .venv/bin/python benchmarks/anchor_limits.py --all --only incisivus=3,orbicularis_oris_peripheralis_lower=3
        --smooth 1e-5 --bound 10 --write-rig sim/face/scan/ict_rig.npz
    # then the corrugator's field over its zone grown 1.5 cm ("The brows carried whole")
    nice .venv/bin/python benchmarks/anchor_limits.py --all --only corrugator=1.5 --smooth 1e-4 --bound 10
        --write-rig sim/face/scan/ict_rig.npz
    # the nose wing's slip (sim.face.scan.make_rig.ala_slip) and the upper lip's elevators refitted on it
    nice .venv/bin/python benchmarks/anchor_limits.py --ala-slip --all --only levator_labii,levator_labii_alaeque_nasi
        --grow 1.5 --smooth 1e-4 --bound 10 --add --write-rig sim/face/scan/ict_rig.npz

`--even W` joins the forehead's evenness to the objective: the lumps (`sim.face.scan.anchor_fit.
forehead_lumps`, what the displacement keeps beyond its 1 cm average, the figure tests/sim/test_scan_face.py
holds) of the poses `--even-poses` (the scanned head's surprise and AU1+2 at full), settled on the
rig the fit starts from, with the fields' linear change, relative to each pose's forehead displacement
and weighted W; `--even-keep W2` holds those poses' smooth part (their 1 cm average from 1 cm above the
upper lids: the brows' lift) where it was. With `--settle --rounds R` the terms are taken about the
settled poses too. The frontalis' fields refitted so, on the rig the commands above made ("Surprise's forehead evened",
docs/scan-face.md):

    nice .venv/bin/python benchmarks/anchor_limits.py --all --only frontalis_inner=1.5,frontalis_outer --smooth 1e-4
        --bound 10 --even 100 --even-keep 30 --settle --rounds 1 --write-rig sim/face/scan/ict_rig.npz

The later commands, each run once in this order on the rig the commands above made (the rig that
ships; docs/scan-face.md has each one's section):

    # the lids' tissue ("The blink's lid fold held: the lid channel's tissue"): the lid channel's
    # field with the closed lids held meeting (--hold), then the orbital orbicularis' refitted
    nice .venv/bin/python benchmarks/anchor_limits.py --all --only orbicularis_oculi_lid=0.5 --smooth 1e-4 --bound 10
        --hold AU45 --hold-weight 30 --hold-close 0.5 --write-rig sim/face/scan/ict_rig.npz
    nice .venv/bin/python benchmarks/anchor_limits.py --all --only orbicularis_oculi=5 --smooth 1e-4 --bound 10
        --write-rig sim/face/scan/ict_rig.npz
    # the mouth corner's muscles' fields over zones grown 3 cm (the zygomaticus major, the risorius,
    # the buccinator and the corner's elevator carrying the cheek's tissue; "The smile's cheek: the
    # corner's muscles over grown zones")
    nice .venv/bin/python benchmarks/anchor_limits.py --all --only zygomaticus_major=3,risorius=3,buccinator=3,
        levator_anguli_oris=3 --smooth 1e-4 --bound 10 --write-rig sim/face/scan/ict_rig.npz
    # the lips' lift (the lip_lift channel's two patches, sim.face.scan.make_rig.lip_lift; ARKit
    # mouthClose, "mouthClose: the lips lifted")
    nice .venv/bin/python -m sim.face.scan.make_rig --lip-lift
    # the puff's pressure over the vestibule and the rolls' margins (sim.face.scan.make_rig), then the
    # puff's, the rolls' and the pressed halves' fields over grown zones ("The lips and the puff")
    .venv/bin/python -m sim.face.scan.make_rig --puff-vestibule
    .venv/bin/python -m sim.face.scan.make_rig --roll-margins
    nice .venv/bin/python benchmarks/anchor_limits.py --all --only cheek_puff=1,orbicularis_oris_marginalis_upper=3,
        orbicularis_oris_marginalis_lower=3,orbicularis_oris_l=3,orbicularis_oris_r=3 --smooth 1e-5 --bound 10 --settle
        --write-rig sim/face/scan/ict_rig.npz
    # the jaw's hinge fitted to the scan's jawOpen and the skin's jaw weights to the settled jaw
    # shapes ("The jaw's hinge and the skin carried by the mandible"), then the corner depressor's
    # and the stretcher's fields, and the lips' sideways band's, over zones grown 3 cm
    nice .venv/bin/python -m sim.face.scan.jaw_fit --rig sim/face/scan/ict_rig.npz
    nice .venv/bin/python benchmarks/anchor_limits.py --all --only risorius=3,depressor_anguli_oris=3 --smooth 1e-4
        --bound 10 --add --settle --write-rig sim/face/scan/ict_rig.npz
    nice .venv/bin/python benchmarks/anchor_limits.py --all --only mouth_shift=3 --smooth 1e-4 --bound 10 --add
        --settle --write-rig sim/face/scan/ict_rig.npz
    # the tissue round the globe carried by the turning eye: the eight look fields (FaceRig.gaze) fitted
    # to the scan's eyeLook shapes ("The tissue round the globe carried by the turning eye")
    nice .venv/bin/python benchmarks/gaze_tissue.py --write-rig sim/face/scan/ict_rig.npz
    # the upper lip's elevators pushing the infraorbital triangle out (sim.face.scan.make_rig.levator_bulge)
    # with their fields refitted on it, then the upper pars peripheralis turned up (make_rig.shrug_up)
    # ("The infraorbital triangle's bulge and the upper lip's shrug")
    nice .venv/bin/python benchmarks/anchor_limits.py --levator-bulge --all --only levator_labii,levator_labii_alaeque_nasi
        --grow 1.5 --smooth 1e-4 --bound 10 --add --settle --write-rig sim/face/scan/ict_rig.npz
    .venv/bin/python -m sim.face.scan.make_rig --shrug-up
    # the orbital orbicularis' field refitted again over its zone grown 5 cm with a ridge a hundredth of
    # the default (the malar fat carried further up and forward: "The cheek's squint: the malar fat
    # carried further")
    nice .venv/bin/python benchmarks/anchor_limits.py --all --only orbicularis_oculi=5 --smooth 1e-5 --ridge 1e-7
        --bound 10 --write-rig sim/face/scan/ict_rig.npz
    # the lower lip's turning: the rolled lower lip's sulcus swung forward (sim.face.scan.make_rig.
    # roll_sulcus; ARKit mouthRollLower, "The lower lip's turning: the sulcus filled")
    .venv/bin/python -m sim.face.scan.make_rig --roll-sulcus
    # the mentalis' pout: its two bellies together push the lower red lip out and up, not its sided
    # halves (sim.face.scan.make_rig.mentalis_pout; ARKit mouthShrugLower, "The mentalis' pout")
    .venv/bin/python -m sim.face.scan.make_rig --mentalis-pout
    # the corrugator's field over its zone grown 4.5 cm: the brow's layer carrying the temple beside
    # the brow's tail ("The temple carried with the brows"; the scanned head's fear at AU4 0.6)
    nice .venv/bin/python benchmarks/anchor_limits.py --all --only corrugator=4.5 --smooth 1e-4 --bound 10 --settle
        --write-rig sim/face/scan/ict_rig.npz
    # the corner's four fields refitted over the same zones on the merged rig, with the ARKit map's
    # smile and stretch refitted ("The mouth corner's shapes again")
    nice .venv/bin/python benchmarks/anchor_limits.py --all --only zygomaticus_major=3,risorius=3,buccinator=3,
        levator_anguli_oris=3 --smooth 1e-4 --bound 10 --write-rig sim/face/scan/ict_rig.npz
    # the platysma (AU21, platysma_l/_r; sim.face.scan.make_rig.platysma): its patches over the jowl
    # and under the chin; no field of its own (fitted on jawOpen it took 0.241 to 0.241, "The platysma")
    .venv/bin/python -m sim.face.scan.make_rig --platysma
    # the depressors' and the upper lip's elevators' fields refitted with a ridge a hundredth of the default
    # (their tissue carried further: "The depressors' and the elevators' fields carried further")
    nice .venv/bin/python benchmarks/anchor_limits.py --all --only depressor_anguli_oris=3,depressor_labii=3 --smooth 1e-5
        --ridge 1e-7 --bound 10 --add --write-rig sim/face/scan/ict_rig.npz
    nice .venv/bin/python benchmarks/anchor_limits.py --all --only levator_labii=1.5,levator_labii_alaeque_nasi=1.5
        --smooth 1e-5 --ridge 1e-7 --bound 10 --add --write-rig sim/face/scan/ict_rig.npz

`--hold POSE,..` keeps, in each pose (a preset on the scanned head, or AUs joined by '+'), how far the
upper lids' margins move against the lower margins beneath them where the rig the fit starts from
settled them (`margin_rows`; weighted `--hold-weight` over that motion's size, squared): closed lids
still meet, while both lids may move together; `--hold-close MM` asks the upper margins MM further down
than that (the settled lids opened 0.2 mm more than the linear model held them: the contact stops
them where they meet).

`--levator-bulge` first adds the infraorbital triangle's bulge to both elevators of the upper lip
(`sim.face.scan.make_rig.levator_bulge`), as `--ala-slip` adds the nose wing's slip. `--nasolabial`
first gives the skin along the nasolabial fold a laxer support (`nasolabial_fold`; tried there, not
shipped).

`--tether S` fits the fields in the linear statics of the skin with its tether (`rest_stiffness`) S
times as stiff, in the stiffness and in the fields' force alike, on top of the shipped skin's settled
poses: how much more of what they miss the same smooth fields could shape on a stiffer tie (a
measurement only: no --settle, no --write-rig; docs/scan-face.md, "The mouth corner's shapes again").

`--per-shape zones|skin` fits a field per shape instead (as if each shape had its own channel: over
its channels' zones, grown by `--grow`, or over all the free skin), the ceiling of more channels or
parts; `--where` prints where each shape's error lies (`face_regions.py`). `--keep` leaves those
channels' fields as the rig has them, `--leave` leaves those shapes out of the fit; `--write-rig
--add` adds the fitted fields to the rig's own (the fit is of what the rig's settled poses miss; so
does `--only`). docs/scan-face.md ("A shape's own anchors, and where the median's error lies") has
those figures and the commands that wrote the shipped rig.

`--settle` applies the fitted fields to the running simulator (their force k_r d joins each
channel's response in the implicit step: no recompile) and settles every shape from rest;
`--rounds R` then refits R times about the settled poses (the linear model's change from the
current fields added to what the simulator settled, the step damped by `--damp`), settling again
after each. `--scale` also settles the fields scaled by each given factor. `--save FILE` keeps the
fitted per-channel displacement fields (cm). `--settled FILE` caches the shipped rig's settled
poses. docs/scan-face.md ("The tissue under the skin moving with the muscle") has the figures.

    nice .venv/bin/python benchmarks/anchor_limits.py [--smooth 1e-3] [--grow 0] [--bound 5] [--iters 300]
        [--settle [--rounds R] [--damp 0.5] [--scale 0.5,0.25]] [--save FILE] [--all] [--settled FILE] [--levator-bulge]
        [--per-shape zones|skin] [--where] [--only C[=GROW],..] [--keep C,..] [--leave S,..] [--write-rig RIG [--add]]
        [--settle [--rounds R] [--damp 0.5] [--scale 0.5,0.25]] [--save FILE] [--all] [--settled FILE]
        [--per-shape zones|skin] [--tether S] [--where] [--only C[=GROW],..] [--keep C,..] [--leave S,..] [--write-rig RIG [--add]]
        [--even W [--even-keep W2] [--even-poses surprise,AU1+2]] [--hold AU45 [--hold-weight 30] [--hold-close 0.5]]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

STILL_MM = 0.3


def rms(d: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.sum(d * d, axis=1))))


class AnchoredSettler:
    """A Settler whose channels carry extra constant forces (N, 3) per channel at full value,
    written into the implicit step's responses (as `sim.fit.rig_settled.InsertionBumps` does)."""

    def __init__(self, model) -> None:  # type: ignore[no-untyped-def]
        from sim.fit.basis import Settler

        self.settler = Settler(model)
        st = self.settler.sim._implicit  # type: ignore[attr-defined]
        if st is None:
            raise ValueError("needs the implicit integrator")
        st._resp = np.array(st._resp)  # this simulator's own copy
        self.stepper, self.base = st, st._resp.copy()
        self.free = np.asarray(st.prepared["free"])
        self.model = model

    def apply(self, forces: dict[str, np.ndarray]) -> None:
        self.stepper._resp[...] = self.base
        for c, f in forces.items():
            out = np.zeros((len(self.free), 3))
            self.stepper.solver.solve(np.ascontiguousarray(f[self.free]), out)
            self.stepper._resp[self.model.channel_index[c]] += out

    def displacement(self, values: np.ndarray) -> np.ndarray:
        return self.settler.pose(values) - self.settler.rest


def nasolabial_fold(rig, width: float = 0.5, support: float = 0.3):  # type: ignore[no-untyped-def]
    """The rig with the skin within `width` cm of each nasolabial fold's line (the nose wing's landmark
    to 8 mm outside and 3 mm below the mouth's corner, as `face_regions` draws it) resisting
    indentation `support` times as much (`FaceRig.tissue["support_nasolabial"]`): no malar fat holds
    the fold's skin out, so it sinks as the corner is drawn back."""
    from dataclasses import replace

    rest = np.asarray(rig.mesh.vertices, float)
    lm = rig.mesh.landmarks
    dist = np.full(len(rest), np.inf)
    for side, sign in (("l", 1.0), ("r", -1.0)):
        a = rest[lm[f"nose_wing_{side}"]]
        b = rest[lm[f"mouth_corner_{side}"]] + np.array([0.8 * sign, -0.3, 0.0])
        t = np.clip((rest - a) @ (b - a) / float((b - a) @ (b - a)), 0.0, 1.0)
        dist = np.minimum(dist, np.linalg.norm(rest - (a + t[:, None] * (b - a)), axis=1))
    return replace(rig, tissue={**rig.tissue, "support_nasolabial": np.where(dist <= width, support, 1.0)})


def refit_zones(model, spec: list[str], grow: float) -> dict[str, np.ndarray]:  # type: ignore[no-untyped-def]
    """The zones of the channels named in `spec` (items NAME or NAME=GROW: a channel, or a muscle's
    base name for both its sides; each zone grown by its GROW cm over the skin, `grow` where none)."""
    from sim.face.scan.anchor_fit import channel_zones

    out: dict[str, np.ndarray] = {}
    for item in spec:
        base, _, g = item.partition("=")
        zones = channel_zones(model, float(g) if g else grow)
        named = {c: z for c, z in zones.items() if c in (base, base + "_l", base + "_r")}
        if not named:
            raise SystemExit(f"--only: {base} is no muscle channel of the scanned head")
        out.update(named)
    return {c: out[c] for c in sorted(out, key=model.channel_index.__getitem__)}  # in the model's order


def summary(name: str, rel: np.ndarray, held: np.ndarray) -> None:
    for what, m in (("all", np.ones(len(rel), bool)), ("fitted", ~held), ("held out", held)):
        if m.any():
            print(f"  {name} {what} ({m.sum()}): median {np.median(rel[m]):.3f} max {rel[m].max():.3f}, "
                  f"{int(np.sum(rel[m] > 0.6))} above 0.6", flush=True)


class _ShapeChannels:
    """The compiled model seen with one pseudo-channel per scanned shape (its `channel_index`)."""

    def __init__(self, model, labels: list[str]) -> None:  # type: ignore[no-untyped-def]
        self._model = model
        self.channel_index = {lab: k for k, lab in enumerate(labels)}

    def __getattr__(self, name: str):  # type: ignore[no-untyped-def]
        return getattr(self._model, name)


class _Tethered:
    """The compiled model seen with its skin's tether (`rest_stiffness`, the tie to the tissue beneath)
    scaled by `scale`: the linear statics of a stiffer or laxer tether against the same membrane."""

    def __init__(self, model, scale: float) -> None:  # type: ignore[no-untyped-def]
        self._model = model
        self.rest_stiffness = np.asarray(model.rest_stiffness, np.float64) * scale

    def __getattr__(self, name: str):  # type: ignore[no-untyped-def]
        return getattr(self._model, name)


def per_shape_calibration(model, labels: list[str], vals: np.ndarray, args):  # type: ignore[no-untyped-def]
    """An AnchorCalibration with one field per shape (no mirroring: each shape is its own group)
    and the shapes' values as the identity (each shape drives its own field at 1)."""
    from sim.face.scan.anchor_fit import AnchorCalibration, channel_zones

    held = np.asarray(model.held, bool)
    if args.per_shape == "skin":
        skin = (np.asarray(model.rest_stiffness) > 0) & ~held
        zones = {lab: skin for lab in labels}
    else:
        by_channel = channel_zones(model, args.grow)
        zones = {}
        for k, lab in enumerate(labels):
            z = np.zeros(len(held), bool)
            for c, zc in by_channel.items():
                if vals[k, model.channel_index[c]] != 0:
                    z |= zc
            zones[lab] = z
    zones = {lab: z for lab, z in zones.items() if z.any()}
    cal = AnchorCalibration(model, smooth=args.smooth, ridge=args.ridge, bound=args.bound, zones=zones)
    cal.model = _ShapeChannels(model, labels)
    print(f"per-shape fields: {len(zones)} of {len(labels)} shapes have a zone; zone sizes median "
          f"{int(np.median([z.sum() for z in zones.values()]))} vertices", flush=True)
    return cal, np.eye(len(labels))


def lumps_mm(smoothing, u: np.ndarray) -> str:  # type: ignore[no-untyped-def]
    """The largest and 95th percentile lump (`sim.face.scan.anchor_fit.forehead_lumps`) of u (N, 3) cm."""
    lump = 10.0 * np.linalg.norm((smoothing @ np.ravel(u)).reshape(-1, 3), axis=1)
    return f"{lump.max():.2f} / {np.percentile(lump, 95):.2f}"


def even_poses(model, cal, anch, args) -> list:  # type: ignore[no-untyped-def]
    """The --even terms joined to the calibration: per pose its name, channel values, displacement
    settled on the rig the fit starts from and the lumps' matrix."""
    from sim.face.scan.anchor_fit import forehead_lumps

    if anch is None:
        raise SystemExit("--even settles its poses: leave out --settled")
    s = forehead_lumps(model)
    keep = forehead_lumps(model, low=1.0, average=True)
    out = []
    for pose in (x for x in args.even_poses.split(",") if x):
        c = pose_control(pose)
        u0 = anch.displacement(c.values)
        size = float(np.sum(u0.ravel()[np.unique(s.indices)] ** 2))
        cal.even_over(c.values, u0, s, args.even / size)
        if args.even_keep > 0:  # the pose's smooth lift (the brows' with it) kept
            cal.even_over(c.values, u0, keep, args.even_keep / size, keep @ u0.ravel())
        out.append((pose, c.values.copy(), u0, s))
        print(f"even: {pose} lumps {lumps_mm(s, u0)} mm settled", flush=True)
    return out


def pose_control(pose: str):  # type: ignore[no-untyped-def]
    """A preset on the scanned head, or action units joined by '+' (`sim.face.targets.pose_control`)."""
    from sim.face import targets as et
    from sim.facs import EXPRESSIONS, apply_expression
    from sim.state import FaceControl

    if pose in EXPRESSIONS:
        c = FaceControl()
        apply_expression(c, pose, face="ict")
        return c
    return et.pose_control(pose)


def margin_rows(model):  # type: ignore[no-untyped-def]
    """(3M, 3N) sparse: a displacement (3N,) of the scanned head to how far its upper lids' margins
    move against the lower margins beneath them (M: both eyes' upper margin vertices, each less the
    lower margin's vertex nearest across the face at rest), what keeps closed lids meeting while
    both lids may move together."""
    import scipy.sparse as sp

    from sim.face.transfer.eyes import mesh_lids

    rest = np.asarray(model.rest)
    pairs = []
    for k in (0, 1):
        upper, lower = (np.asarray(a) for a in mesh_lids(model.mesh, k))
        below = lower[np.argmin(np.abs(rest[upper, 0][:, None] - rest[lower, 0][None]), axis=1)]
        pairs.append(np.stack([upper, below], axis=1))
    p = np.concatenate(pairs)
    m = len(p)
    a = sp.csr_matrix((np.r_[np.ones(m), -np.ones(m)], (np.r_[np.arange(m), np.arange(m)], np.r_[p[:, 0], p[:, 1]])),
                      shape=(m, len(rest)))
    return sp.kron(a, sp.eye(3)).tocsr()


def hold_margins(model, cal, anch, args) -> list:  # type: ignore[no-untyped-def]
    """The --hold terms joined to the calibration: per pose the upper lids' margins kept where the rig
    the fit starts from settled them against the lower margins (`margin_rows`) (`AnchorCalibration.even_over` with the margins' rows and their
    settled displacement as the target), weighted `--hold-weight` over that displacement's size.
    Returns per pose (name, channel values, settled displacement, rows)."""
    if anch is None:
        raise SystemExit("--hold settles its poses: leave out --settled")
    s = margin_rows(model)
    out = []
    for pose in (x for x in args.hold.split(",") if x):
        c = pose_control(pose)
        u0 = anch.displacement(c.values)
        su = s @ u0.ravel()
        close = np.zeros(s.shape[0])
        close[1::3] = -0.1 * args.hold_close  # the upper margins asked this much further down (cm)
        cal.even_over(c.values, u0, s, args.hold_weight / float(su @ su), su + close)
        out.append((pose, c.values.copy(), u0, s))
        print(f"hold: {pose} margins moved {margin_mm(s, u0)} mm settled", flush=True)
    return out


def margin_mm(rows, u: np.ndarray) -> str:  # type: ignore[no-untyped-def]
    """The largest and median of the upper margins' displacement against the lower ones, mm."""
    m = 10.0 * np.linalg.norm((rows @ np.ravel(u)).reshape(-1, 3), axis=1)
    return f"{m.max():.2f} / {np.median(m):.2f}"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--smooth", type=float, default=1e-3, help="Laplacian weight per edge and component (per mm^2)")
    ap.add_argument("--ridge", type=float, default=1e-5, help="pull of each component towards 0 (per mm^2)")
    ap.add_argument("--bound", type=float, default=5.0, help="bound of each component, mm")
    ap.add_argument("--grow", type=float, default=0.0, help="grow each channel's zone by this many cm")
    ap.add_argument("--iters", type=int, default=300, help="L-BFGS-B iterations at most")
    ap.add_argument("--settled", type=Path, help="cache of the shipped rig's settled poses (read if present, else written)")
    ap.add_argument("--settle", action="store_true", help="settle every shape on the simulator with the fitted fields")
    ap.add_argument("--rounds", type=int, default=0, help="with --settle: refits about the settled poses")
    ap.add_argument("--damp", type=float, default=0.5, help="with --rounds: the share of each refit's step taken")
    ap.add_argument("--scale", default="", help="with --settle: also settle the fields scaled by these factors")
    ap.add_argument("--save", type=Path, help="write the fitted fields here (npz, channel -> (N,3) cm)")
    ap.add_argument("--write-rig", type=Path, help="write the scanned head's rig with the fitted fields here (FaceRig.anchor)")
    ap.add_argument("--add", action="store_true", help="with --write-rig: add the fitted fields to the rig's own "
                    "anchors (the fit is of what the rig's settled poses miss; --only always adds)")
    ap.add_argument("--all", action="store_true", help="fit on all shapes (no held-out right ones)")
    ap.add_argument("--shapes", default="", help="only these labels (comma separated)")
    ap.add_argument("--rig", type=Path, help="start from this rig file of the scanned head instead of the shipped one")
    ap.add_argument("--ala-slip", action="store_true",
                    help="add the nose wing's slip to the rig (sim.face.scan.make_rig.ala_slip) before the fit")
    ap.add_argument("--levator-bulge", action="store_true",
                    help="add the infraorbital triangle's bulge to the rig (sim.face.scan.make_rig.levator_bulge) before the fit")
    ap.add_argument("--nasolabial", action="store_true",
                    help="give the nasolabial fold's skin a laxer support first (nasolabial_fold), then fit on it")
    ap.add_argument("--halves", action="store_true", help="fit the sided halves' fields alone, the others kept")
    ap.add_argument("--only", "--channels", dest="only", default="",
                    help="refit these channels' fields alone (NAME[=GROW], comma separated: a channel or a muscle's "
                         "base name for both sides, its zone grown GROW cm, default --grow), added to the rig's, "
                         "the others kept")
    ap.add_argument("--per-shape", choices=("", "zones", "skin"), default="",
                    help="a field per scanned shape instead of per channel, as if each shape had its own channel: "
                         "over the zones of the channels its map entry drives ('zones', grown by --grow) or over "
                         "all the free skin ('skin'); every shape fitted (no held-out ones)")
    ap.add_argument("--keep", default="", help="channels (comma-separated; a name without _l/_r both sides) whose fields are not fitted "
                    "(left as the rig has them)")
    ap.add_argument("--leave", default="", help="shapes (comma-separated labels or prefixes) left out of the fit "
                    "(still settled and printed)")
    ap.add_argument("--even", type=float, default=0.0,
                    help="weight of the forehead's evenness in the objective (its lumps in --even-poses, relative "
                         "to each pose's forehead displacement, squared)")
    ap.add_argument("--even-keep", type=float, default=0.0,
                    help="with --even: weight of keeping those poses' smooth part (their 1 cm average from 1 cm above "
                         "the upper lids up, the brows' lift) as the rig before settled it")
    ap.add_argument("--even-poses", default="surprise,AU1+2",
                    help="with --even: the poses (a preset on the scanned head, or AUs joined by '+') whose lumps count")
    ap.add_argument("--hold", default="",
                    help="poses (a preset on the scanned head, or AUs joined by '+') whose lid margins the fields "
                         "keep where the rig the fit starts from settled them (the closed lids still meet)")
    ap.add_argument("--hold-weight", type=float, default=100.0,
                    help="with --hold: weight of the margins' change, relative to their displacement, squared")
    ap.add_argument("--hold-close", type=float, default=0.0,
                    help="with --hold: the upper margins held this many mm further down against the lower ones than "
                         "the rig settled them (the contact stops them where the lids meet)")
    ap.add_argument("--tether", type=float, default=1.0,
                    help="fit the fields in the linear statics of the skin with its tether this many times as stiff "
                         "(the settled poses, and --settle, stay the shipped skin's)")
    ap.add_argument("--where", action="store_true", help="print where each shape's remaining error lies (regions)")
    args = ap.parse_args()
    from scan_match import scan_targets

    from puppet.capture.arkit_in import shape_channels
    from puppet.face_cache import scan_model
    from sim.face.scan.anchor_fit import AnchorCalibration

    from sim.build import compile_model
    from sim.channels import HALVES
    from sim.face.scan.anchor_fit import half_anchors
    from sim.face.scan.rig import RIG_FILE, scan_params
    from sim.rig import load_rig

    t0 = time.monotonic()
    only_fit = set(HALVES) if args.halves else {c for c in args.only.split(",") if c}
    start_rig = load_rig(args.rig or RIG_FILE)
    if args.ala_slip:  # the nose wing's slip first (sim.face.scan.make_rig.ala_slip), then the fit on it
        from sim.face.scan.make_rig import ala_slip

        start_rig = ala_slip(start_rig)
    if args.levator_bulge:  # the infraorbital triangle's bulge (sim.face.scan.make_rig.levator_bulge), then the fit on it
        from sim.face.scan.make_rig import levator_bulge

        start_rig = levator_bulge(start_rig)
    if args.nasolabial:  # likewise the nasolabial fold's laxer support
        start_rig = nasolabial_fold(start_rig)
    if args.halves:
        start_rig = half_anchors(start_rig)
        model = compile_model(start_rig, scan_params())
    elif args.rig or only_fit or args.ala_slip or args.levator_bulge or args.nasolabial:
        model = compile_model(start_rig, scan_params())
    else:
        model = scan_model()
    zones = refit_zones(model, sorted(only_fit), args.grow) if only_fit else None
    cache = dict(np.load(args.settled)) if args.settled and args.settled.exists() else None
    anch = AnchoredSettler(model) if (cache is None or args.settle) else None
    labels, vals, targets, real = [], [], [], []
    only = set(args.shapes.split(",")) if args.shapes else None
    for label, (shape, target) in scan_targets(None).items():
        if rms(target) * 10 < STILL_MM or (only and label not in only):
            continue
        v = shape_channels({shape: np.ones(1)}, 1)[0]
        if zones and not any(v[model.channel_index[c]] > 0 for c in zones):
            continue
        labels.append(label)
        vals.append(v)
        targets.append(target)
        real.append(anch.displacement(v) if cache is None else cache[label])  # type: ignore[union-attr]
    vals_a = np.array(vals)
    if args.settled and cache is None:
        np.savez(args.settled, **dict(zip(labels, real)))
    print(f"{len(labels)} shapes settled in {time.monotonic() - t0:.0f} s", flush=True)
    fit_model = model if args.tether == 1.0 else _Tethered(model, args.tether)
    if args.tether != 1.0 and (args.settle or args.write_rig):
        raise SystemExit("--tether is a measurement of the linear statics: leave out --settle and --write-rig")
    if args.per_shape:
        cal, vals_a = per_shape_calibration(fit_model, labels, vals_a, args)
        args.all = True
    else:
        if zones is None and args.keep:  # every channel's field but the kept ones
            from sim.face.scan.anchor_fit import channel_zones

            keep = {x for x in args.keep.split(",") if x}
            zones = {c: z for c, z in channel_zones(model, args.grow).items()
                     if c not in keep and c.removesuffix("_l").removesuffix("_r") not in keep}
        cal = AnchorCalibration(fit_model, smooth=args.smooth, ridge=args.ridge, bound=args.bound, grow=args.grow,
                                zones=zones)
    print(f"anchor fields: {cal.n_params} parameters over {len(cal.groups)} muscles "
          f"({time.monotonic() - t0:.0f} s)", flush=True)
    even = even_poses(model, cal, anch, args) if args.even > 0 else []
    held_poses = hold_margins(model, cal, anch, args) if args.hold else []
    leave = tuple(x for x in args.leave.split(",") if x)
    train = [k for k, lab in enumerate(labels) if (args.all or not lab.endswith("_R"))
             and not (leave and lab.startswith(leave))]
    held = np.array([k not in train for k in range(len(labels))])
    w = np.array([1.0 / float(np.sum(targets[k] ** 2)) for k in train])
    tg = [targets[k].ravel() for k in range(len(labels))]
    b = np.stack([tg[k] - real[k].ravel() for k in train], axis=1)
    res = cal.fit(vals_a[train], b, w, iters=args.iters)
    print(f"fitted in {time.monotonic() - t0:.0f} s: {res.nit} iterations, {res.message}", flush=True)
    add = cal.predict_all(vals_a)
    before = np.array([rms(real[k] - targets[k]) / rms(targets[k]) for k in range(len(labels))])
    after = np.array([rms(real[k] + add[k] - targets[k]) / rms(targets[k]) for k in range(len(labels))])
    print(f"{'shape':22s} {'settled':>8s} {'+anchors':>8s}")
    for k, lab in enumerate(labels):
        print(f"{lab:22s} {before[k]:8.3f} {after[k]:8.3f}{'' if k in train else '  (held out)'}")
    summary("settled", before, held)
    summary("+ anchors (linear)", after, held)
    if args.where:
        from face_regions import print_scales, print_where

        print_where(model, labels, targets, real, "settled")
        print_scales(model, labels, targets, real, "settled")
        print_where(model, labels, targets, [real[k] + add[k] for k in range(len(labels))], "+ anchors (linear)")
    for pose, v, u0, s in even:
        print(f"{pose} lumps, max / p95 mm: settled {lumps_mm(s, u0)}, + anchors (linear) "
              f"{lumps_mm(s, u0 + cal.predict_all(v[None])[0])}", flush=True)
    p = cal.params.reshape(-1, 3)
    mag = np.linalg.norm(p, axis=1)
    dp = (cal.diff @ cal.params).reshape(-1, 3)
    print(f"anchor displacement at full value, mm: median {np.median(mag):.2f}, 95th {np.percentile(mag, 95):.2f}, "
          f"max {mag.max():.2f}; change across an edge: median {np.median(np.linalg.norm(dp, axis=1)):.3f}, "
          f"95th {np.percentile(np.linalg.norm(dp, axis=1), 95):.3f}", flush=True)
    if args.settle:
        assert anch is not None

        def settle_with(params: np.ndarray) -> list[np.ndarray]:
            anch.apply({c: cal.force(c, params) for c in cal.channels})
            return [anch.displacement(vals[k]) for k in range(len(labels))]

        def report(name: str, sim: list[np.ndarray]) -> np.ndarray:
            rel = np.array([rms(sim[k] - targets[k]) / rms(targets[k]) for k in range(len(labels))])
            print("  " + ", ".join(f"{lab} {r:.3f}" for lab, r in zip(labels, rel)))
            summary(name, rel, held)
            return rel

        sim = settle_with(cal.params)
        report("settled with anchors (simulator)", sim)
        for pose, v, u0, rows in held_poses:
            u1 = anch.displacement(v)
            print(f"{pose} margins, max / median mm: settled {margin_mm(rows, u0)}, with anchors {margin_mm(rows, u1)}, "
                  f"moved by them {margin_mm(rows, u1 - u0)}", flush=True)
        for pose, v, u0, s in even:
            print(f"{pose} lumps, max / p95 mm, settled with anchors: {lumps_mm(s, anch.displacement(v))}", flush=True)
        for s in [float(x) for x in args.scale.split(",") if x]:
            report(f"settled with anchors x{s}", settle_with(s * cal.params))
        for r in range(args.rounds):
            lin = cal.predict_all(vals_a)
            b = np.stack([tg[k] - sim[k].ravel() + lin[k].ravel() for k in train], axis=1)
            for j, (pose, v, _, s) in enumerate(even):  # the evenness about the settled poses too
                u0 = anch.displacement(v) - cal.predict_all(v[None])[0]
                even[j] = (pose, v, u0, s)
            for j, (pose, v, _, s) in enumerate(held_poses):  # and the held margins
                held_poses[j] = (pose, v, anch.displacement(v) - cal.predict_all(v[None])[0], s)
            by_pose = {e[1].tobytes(): e[2].ravel() for e in even + held_poses}
            cal.even = [(v, by_pose[v.tobytes()], s, wt, t) for v, _, s, wt, t in cal.even]
            p0 = cal.params.copy()
            res = cal.fit(vals_a[train], b, w, iters=args.iters)
            cal.params = p0 + args.damp * (cal.params - p0)
            sim = settle_with(cal.params)
            print(f"round {r + 1} ({res.nit} iterations, {time.monotonic() - t0:.0f} s):", flush=True)
            report(f"round {r + 1} settled", sim)
            for pose, v, _, s in even:
                print(f"{pose} lumps, max / p95 mm, round {r + 1} settled: {lumps_mm(s, anch.displacement(v))}", flush=True)
        anch.apply({})
    if args.save:
        np.savez(args.save, **{c: cal.field(c) for c in cal.channels})
        print(f"wrote {args.save}")
    if args.write_rig:
        from dataclasses import replace

        from sim.rig import save_rig

        if only_fit or args.add:  # the fields' start plus the fitted change; every other field kept
            fields = {c: np.round(np.clip(start_rig.anchor.get(c, 0.0) + cal.field(c), -2.0, 2.0), 6)
                      for c in cal.channels}
            fields = {**start_rig.anchor, **fields}
        else:
            fields = {c: np.round(np.clip(cal.field(c), -2.0, 2.0), 6) for c in cal.channels}
        fields = {c: d for c, d in fields.items() if np.abs(d).max() > 1e-5}
        save_rig(replace(start_rig, anchor=fields), args.write_rig)
        print(f"wrote {args.write_rig} ({len(fields)} channels' anchors)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
