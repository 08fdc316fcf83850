"""Kinematic calibration of the legs from the soles' closure: link length, joint axis and encoder offset errors.

The inverse dynamics barely see a kinematic error (a 4 % longer shank moves lever arms by a centimetre), but the
forward kinematics do. While a foot carries load, the points of its sole on the floor stay put: the sole point when
the foot is flat, the edge (or corner) it rolls on when its COP is near one (:func:`contact_points`). The measured
base pose and joint angles, put through the nominal model, must then place that point at the same place all along.
What it does instead (``closure/<side>/<x|y|z>``: its departure from its median per recording and point, world axes,
m) is what the model's leg kinematics get wrong. Its floor (``CLOSURE_FLOOR_M``) was measured on plants with nothing
kinematic hidden: the soles' own compliance moves them by tenths of a millimetre.

When the closure disagrees (some channel at ``SIGNIFICANT_Z`` floors), the legs' kinematic candidates are
linearised by finite differences of the forward kinematics and chosen greedily (:func:`_forward`), then refined by
Gauss-Newton on the true forward kinematics:

* ``link_length``: a leg link's offset from its parent joint scaled by ``value`` (one leg, or both legs by one
  factor, the link's name with ``*`` for its side, what a symmetric error is);
* ``joint_axis``: a moving leg joint's axis tilted by ``value`` rad toward ``axis x z`` (``axis x x`` for a vertical
  axis) and by ``value_2`` rad toward the axis crossed with that direction (as :func:`gap.effects.alter_model`);
* ``joint_offset``: a moving leg joint's encoder offset (reading - true angle), so that an offset is not taken for a
  length.

Named when the refined fit stays inside ``BOUNDS`` and each effect is at least its kind's ``SMALLEST``; channels
it leaves above the floor are reported as unexplained ("kinematic": a foot that slid is one). The workflow then
evaluates the dynamics with the named lengths and axes (:func:`kinematic_model`), lets them refine the values
(:func:`correction_candidates`) and re-simulates with the altered plant.
"""

from __future__ import annotations

from dataclasses import replace
from fnmatch import fnmatchcase

import numpy as np
import pinocchio as pin

from ..robot.profile import SIDES, Sole, load_profile, profile_of
from ..vectors import xyzw_from_wxyz
from .candidates import stack_rows
from .dataset import Dataset
from .effects import Effect, tilted_axis
from .residuals import body_link_names, evaluate
from .select import SIGNIFICANT_Z, Candidate

CLOSURE_AXES = ("x", "y", "z")
# the closure's RMS on excitation runs with nothing kinematic hidden (seed 1): x 0.32, y 0.06, z 0.03 mm; with soles
# 3 x softer 0.72, 0.09, 0.12 mm. A kinematic error of a few percent gives millimetres (a 4.5 % longer shank: x 3.9,
# z 1.3 mm; one shank 1.6 % short: z 0.6 mm)
CLOSURE_FLOOR_M = {"x": 0.0006, "y": 0.0002, "z": 0.00015}
LOADED_N = 100.0             # a foot with this much vertical load stays where it is
FLAT_MARGIN_M = 0.02         # and lies flat while its centre of pressure is this far inside the sole
STRIDE_S = 0.04              # one sample in this interval enters the fit (the closure is smooth)
MOVING_RAD = 0.1           # a joint whose angle spans this much in the recordings shows its axis
MIN_GAIN = 0.3               # a candidate lowers the closure's squared gap by this share of what is left
MAX_EFFECTS = 4
BOUNDS = {"link_length": (0.8, 1.2), "joint_axis": (-0.2, 0.2), "joint_offset": (-0.2, 0.2)}   # scale; rad; rad
# the smallest error named: a length 0.5 % off (1-2 mm on a thigh or shank), an axis 0.6 degree off, an offset of 2 mrad
# (a tilt of 0.004 rad was fitted to a foot sliding 2 mm on a plant with a knee axis 4.6 degrees off)
SMALLEST = {"link_length": 0.005, "joint_axis": 0.01, "joint_offset": 0.002}
FD_STEP = 1e-4


def closure_channels() -> list[str]:
    """The closure's channel names, side-major."""
    return [f"closure/{s}/{a}" for s in SIDES for a in CLOSURE_AXES]


# -- the model with kinematic effects --------------------------------------------------------------------------------
def kinematic_model(nominal: pin.Model, effects: list[Effect]) -> pin.Model:
    """``nominal`` (copied) with the ``link_length`` and ``joint_axis`` effects of ``effects`` applied."""
    model = nominal.copy()
    links = body_link_names(model)
    for e in effects:
        if e.kind == "link_length":
            for jid in [i + 1 for i, name in enumerate(links) if fnmatchcase(name, e.location)]:
                p = model.jointPlacements[jid]
                model.jointPlacements[jid] = pin.SE3(p.rotation, p.translation * float(e.value))
        elif e.kind == "joint_axis":
            _tilt(model, model.getJointId(e.location), float(e.value), float(e.value_2))
    return model


def _joint_axis(model: pin.Model, jid: int) -> np.ndarray:
    short = model.joints[jid].shortname()
    return {"JointModelRX": np.array([1.0, 0, 0]), "JointModelRY": np.array([0, 1.0, 0]),
            "JointModelRZ": np.array([0, 0, 1.0])}[short]


def _tilt(model: pin.Model, jid: int, t1: float, t2: float) -> None:
    """Rotate joint ``jid``'s axis in place: its frame turned by R0 (axis -> tilted axis) and everything attached to it
    turned back, so that at zero angle the links stay where they were and the motion is about the tilted axis."""
    a = _joint_axis(model, jid)
    b = tilted_axis(a, t1, t2)
    r0 = pin.Quaternion.FromTwoVectors(a, b).matrix()       # about their common normal
    back = pin.SE3(r0.T, np.zeros(3))
    model.jointPlacements[jid] = model.jointPlacements[jid] * pin.SE3(r0, np.zeros(3))
    model.inertias[jid] = back.act(model.inertias[jid])
    for c in range(1, model.njoints):
        if model.parents[c] == jid:
            model.jointPlacements[c] = back * model.jointPlacements[c]
    for f in range(model.nframes):
        frame = model.frames[f]
        if frame.parentJoint == jid:
            frame.placement = back * frame.placement
            model.frames[f] = frame


# -- the closure -----------------------------------------------------------------------------------------------------
class Closure:
    """The soles' closure along every recording with the feet loaded (see the module docstring)."""

    def __init__(self, ds: Dataset, model: pin.Model) -> None:
        self.samples = []       # (recording, index, configuration, per side: its point on the floor or None, its kind)
        for r, rec in enumerate(ds.recordings):
            if rec.static or len(rec) < 3:
                continue
            dt = float(np.median(np.diff(rec.t_s)))
            stride = max(1, int(round(STRIDE_S / dt)))
            loaded = {s: rec.wrench[s][:, 2] > LOADED_N for s in SIDES}
            contact = {s: contact_points(rec.wrench[s], profile_of(model).sole) for s in SIDES}
            for k in range(0, len(rec), stride):
                if any(loaded[s][k] for s in SIDES):
                    self.samples.append((r, k, _pin_q(model, rec.joint_names, rec.base_pose[k], rec.q[k]),
                                         tuple(contact[s][0][k] if loaded[s][k] else None for s in SIDES),
                                         tuple(int(contact[s][1][k]) for s in SIDES)))
        self.floor = np.tile([CLOSURE_FLOOR_M[a] for a in CLOSURE_AXES], len(SIDES))

    def positions(self, nominal: pin.Model, effects: list[Effect]) -> np.ndarray:
        """(S, 2, 3) the soles' world positions [m] under ``nominal`` with the kinematic ``effects`` (link lengths,
        joint axes, encoder offsets), NaN where the foot is not loaded and flat."""
        model = kinematic_model(nominal, effects)
        data = model.createData()
        shift = np.zeros(model.nq)
        for e in effects:
            if e.kind == "joint_offset":                 # reading - true angle
                shift[model.joints[model.getJointId(e.location)].idx_q] += float(e.value)
        frames = [model.getFrameId(f"sole_{s}") for s in SIDES]
        out = np.full((len(self.samples), len(SIDES), 3), np.nan)
        for i, (_r, _k, q, points, _kind) in enumerate(self.samples):
            pin.framesForwardKinematics(model, data, q - shift)
            for j, f in enumerate(frames):
                if points[j] is not None:
                    out[i, j] = data.oMf[f].act(points[j])
        return out

    def residual(self, nominal: pin.Model, effects: list[Effect]) -> np.ndarray:
        """(S, 6) each sole's departure from its median per recording, in floors (NaN where not used)."""
        p = self.positions(nominal, effects)
        rec = np.array([s[0] for s in self.samples])
        for j in range(len(SIDES)):
            point = np.array([s[4][j] for s in self.samples])
            for r, kind in {(a, b) for a, b in zip(rec, point)}:   # one median per point of the sole
                used = (rec == r) & (point == kind) & np.isfinite(p[:, j, 0])
                if used.any():
                    p[used, j] -= np.median(p[used, j], axis=0)
        return p.reshape(len(self.samples), -1) / self.floor

    def z(self, res: np.ndarray) -> np.ndarray:
        """(6,) each channel's RMS in floors (0 where no sample was used)."""
        used = np.isfinite(res)
        ss = np.where(used, res, 0.0) ** 2
        return np.sqrt(ss.sum(axis=0) / np.maximum(used.sum(axis=0), 1))


def contact_points(wrench: np.ndarray, sole: Sole) -> tuple[np.ndarray, np.ndarray]:
    """Per sample, the point of the sole that stays on the floor [m, sole frame] and which one it is (0: the sole
    point, the foot flat; else an edge or a corner): a foot whose centre of pressure is within ``FLAT_MARGIN_M`` of
    an edge rolls about it, and only the edge's points stay put (wrench: world axes, about the sole point; the feet
    point forward)."""
    fz = np.maximum(wrench[:, 2], 1e-9)
    cx, cy = -wrench[:, 4] / fz - sole.centre_x_m, wrench[:, 3] / fz
    hx, hy = sole.half_size_m[0], sole.half_size_m[1]
    sx = np.where(np.abs(cx) > hx - FLAT_MARGIN_M, np.sign(cx), 0.0)      # on the toe (+1) or heel (-1) edge
    sy = np.where(np.abs(cy) > hy - FLAT_MARGIN_M, np.sign(cy), 0.0)      # on the left (+1) or right (-1) edge
    points = np.column_stack([np.where(sx != 0, sole.centre_x_m + sx * hx, 0.0), sy * hy, np.zeros(len(cx))])
    return points, (sx + 1) * 3 + (sy + 1) - 4


def _pin_q(model: pin.Model, names: list[str], base: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Pinocchio configuration: base x y z qw qx qy qz (MuJoCo order) and the joints by name."""
    out = pin.neutral(model)
    out[:3] = base[:3]
    out[3:7] = xyzw_from_wxyz(base[3:7])
    for name, v in zip(names, q):
        if model.existJointName(name):
            out[model.joints[model.getJointId(name)].idx_q] = v
    return out


# -- the fit -----------------------------------------------------------------------------------------------------------
def candidates(ds: Dataset) -> list[tuple[str, str, int]]:
    """(kind, location, number of parameters) of every kinematic candidate of the legs: each link's length (one leg,
    both legs), and the axes of the leg joints that move in the recordings (a still joint's tilt is a constant
    rotation that the closure's median takes out)."""
    profile = load_profile(ds.robot)
    chains = {s: profile.leg_chain(s) for s in SIDES}
    out = []
    for k in range(1, len(chains[SIDES[0]])):          # the links below the first joint set the leg's lengths
        links = {s: profile.child_link(chains[s][k]) for s in SIDES}
        out.append(("link_length", profile.both_sides(links[SIDES[0]]), 1))
        out += [("link_length", links[s], 1) for s in SIDES]
    moving = set()
    for rec in ds.recordings:
        moving |= {n for n, r in zip(rec.joint_names, np.ptp(rec.q, axis=0)) if r >= MOVING_RAD}
    for k in range(len(chains[SIDES[0]])):
        out += [(kind, chains[s][k], n) for s in SIDES if chains[s][k] in moving
                for kind, n in (("joint_axis", 2), ("joint_offset", 1))]
    return out


def _effects(chosen: list[tuple[str, str, int]], theta: np.ndarray) -> list[Effect]:
    """The chosen candidates with parameters ``theta`` (link: scale - 1; axis: the two tilts) as effects."""
    out, i = [], 0
    for kind, loc, n in chosen:
        if kind == "link_length":
            out.append(Effect(kind, loc, value=1.0 + float(theta[i])))
        elif kind == "joint_offset":
            out.append(Effect(kind, loc, value=float(theta[i])))
        else:
            out.append(Effect(kind, loc, value=float(theta[i]), value_2=float(theta[i + 1])))
        i += n
    return out


def _flat(res: np.ndarray) -> np.ndarray:
    x = res.ravel()
    return np.where(np.isfinite(x), x, 0.0)


def _jacobian(closure: Closure, nominal: pin.Model, chosen, theta: np.ndarray, base: np.ndarray) -> np.ndarray:
    """(rows, p) finite-difference Jacobian of the flattened closure residual at ``theta``."""
    cols = []
    for i in range(len(theta)):
        t = theta.copy()
        t[i] += FD_STEP
        cols.append((_flat(closure.residual(nominal, _effects(chosen, t))) - base) / FD_STEP)
    return np.column_stack(cols)


def fit_kinematics(ds: Dataset, nominal: pin.Model, say) -> tuple[list[Effect], dict]:
    """(the named kinematic effects, a report: the closure's per-channel z before and after, what was refused)."""
    closure = Closure(ds, nominal)
    report = {"channels": closure_channels(), "z_before": [], "z_after": [], "refused": [], "unexplained": []}
    if not closure.samples:
        return [], report
    r0 = closure.residual(nominal, [])
    report["z_before"] = report["z_after"] = closure.z(r0).tolist()
    report["unexplained"] = _unexplained(ds, closure, r0)
    if max(report["z_before"]) < SIGNIFICANT_Z:
        return [], report
    say("  the soles move while they carry load: fitting the legs' kinematics (link lengths, joint axes)")
    y0 = _flat(r0)
    pool = candidates(ds)
    lin = {c: _jacobian(closure, nominal, [c], np.zeros(c[2]), y0) for c in pool}
    chosen = _forward(pool, lin, y0, np.isfinite(r0), say)
    if not chosen:
        return [], report
    while True:                    # refined on the true kinematics; what comes out below SMALLEST is dropped
        theta = _gauss_newton(closure, nominal, chosen, y0, np.hstack([lin[c] for c in chosen]))
        found = _effects(chosen, theta)
        keep = [c for c, e in zip(chosen, found) if _matters(e)]
        if len(keep) == len(chosen) or not keep:
            break
        chosen = keep
    after = closure.residual(nominal, found)
    bad = [_describe_bound(e) for e in found if not _inside(e) or not _matters(e)]
    if bad:
        report["refused"] = [{"effect": e.key, "why": "; ".join(bad)} for e in found]
        say(f"  kinematic fit not named: {'; '.join(bad)}")
        return [], report
    z1 = closure.z(after)
    cov = _covariance(closure, nominal, chosen, theta, after)
    _add_intervals(found, cov)
    report["z_after"] = z1.tolist()
    report["unexplained"] = _unexplained(ds, closure, after)
    return found, report


def _forward(pool, lin: dict, y0: np.ndarray, used: np.ndarray, say) -> list[tuple[str, str, int]]:
    """Greedy choice on the linearised closure: while a channel is at ``SIGNIFICANT_Z`` floors, the candidate (fitted
    with those chosen, within its bounds) that lowers those channels' squared residual most, if by ``MIN_GAIN`` of
    their excess over the noise; a candidate that only polishes channels already below is not taken."""
    chosen: list[tuple[str, str, int]] = []
    fit = np.zeros_like(y0)
    while len(chosen) < MAX_EFFECTS:
        res = np.where(used, (y0 + fit).reshape(used.shape), np.nan)
        over = np.zeros_like(used)
        over[:, np.sqrt(np.nanmean(res ** 2, axis=0)) >= SIGNIFICANT_Z] = True
        rows = (over & used).ravel()
        if not rows.any():
            break
        now = float(np.sum((y0 + fit)[rows] ** 2))
        best = None
        for c in pool:
            if c in chosen or _overlaps(c, chosen):
                continue
            X = np.hstack([lin[d] for d in chosen + [c]])
            theta, *_ = np.linalg.lstsq(X, -y0, rcond=None)
            effects = _effects(chosen + [c], theta)
            if not all(_inside(e) for e in effects) or not _matters(effects[-1]):
                continue                   # a fit past the bounds is no explanation (BOUNDS); a tiny one no answer
            s = float(np.sum((y0 + X @ theta)[rows] ** 2))
            if best is None or s < best[0]:
                best = (s, c, X @ theta)
        if best is None or now - best[0] < MIN_GAIN * max(now - rows.sum(), 0.0):
            break
        chosen.append(best[1])
        fit = best[2]
        say(f"    {best[1][0]} @ {best[1][1]}: the disagreeing channels' squared residual {now / rows.sum():.3g} -> "
            f"{best[0] / rows.sum():.3g} per row")
    return chosen


def _overlaps(c, chosen) -> bool:
    """A one-leg link length beside the same link's both-legs one (or the reverse) says the same thing twice."""
    if c[0] != "link_length":
        return False
    k = c[1].split("_")[2]
    return any(d[0] == "link_length" and d[1].split("_")[2] == k for d in chosen)


def _gauss_newton(closure: Closure, nominal: pin.Model, chosen, y0: np.ndarray, X0: np.ndarray) -> np.ndarray:
    """The chosen candidates' parameters on the true forward kinematics, from their linear estimate."""
    theta, *_ = np.linalg.lstsq(X0, -y0, rcond=None)
    for _ in range(3):
        y = _flat(closure.residual(nominal, _effects(chosen, theta)))
        J = _jacobian(closure, nominal, chosen, theta, y)
        step, *_ = np.linalg.lstsq(J, -y, rcond=None)
        theta = theta + step
        if np.max(np.abs(step)) < 1e-6:
            break
    return theta


def _covariance(closure: Closure, nominal: pin.Model, chosen, theta: np.ndarray, after: np.ndarray) -> np.ndarray:
    """The parameters' covariance: the residual's scale left after the fit, with the rows' smoothness counted (one
    independent row per ``STRIDE_S`` is optimistic: the closure varies over a move, ~1 s)."""
    y = _flat(after)
    J = _jacobian(closure, nominal, chosen, theta, y)
    n_eff = max(len(closure.samples) * STRIDE_S, len(theta) + 1.0)
    s2 = float(y @ y) / max(len(y) - len(theta), 1) * len(y) / n_eff
    return s2 * np.linalg.pinv(J.T @ J)


def _add_intervals(found: list[Effect], cov: np.ndarray) -> None:
    se = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    i = 0
    for e in found:
        e.ci95, e.unit = 1.96 * float(se[i]), "x the model's offset" if e.kind == "link_length" else "rad"
        e.share_of_gap, e.delta_bic, e.alternatives = 0.0, 0.0, ()
        if e.kind == "joint_axis":
            e.ci95_2 = 1.96 * float(se[i + 1])
        i += 2 if e.kind == "joint_axis" else 1


def _matters(e: Effect) -> bool:
    """Whether an estimate is at least its kind's ``SMALLEST``: below, a fit only follows a foot's slip."""
    size = abs(e.value - 1.0) if e.kind == "link_length" else float(np.hypot(e.value, e.value_2))
    return size >= SMALLEST[e.kind]


def _inside(e: Effect) -> bool:
    lo, hi = BOUNDS[e.kind]
    return all(lo <= float(v) <= hi for v in ((e.value,) if e.kind == "link_length" else (e.value, e.value_2)))


def _describe_bound(e: Effect) -> str:
    lo, hi = BOUNDS[e.kind]
    if not _matters(e):
        return f"{e.key} below the smallest error named ({SMALLEST[e.kind]})"
    return f"{e.key} past its bounds [{lo}, {hi}]"


def _unexplained(ds: Dataset, closure: Closure, res: np.ndarray) -> list[dict]:
    """The closure channels still above ``SIGNIFICANT_Z`` floors per recording, with when."""
    out = []
    rec_of = np.array([s[0] for s in closure.samples])
    for r in np.unique(rec_of):
        m = rec_of == r
        t = ds.recordings[r].t_s[[s[1] for s, keep in zip(closure.samples, m) if keep]]
        z = closure.z(res[m])
        for c, ch in enumerate(closure_channels()):
            if not z[c] > SIGNIFICANT_Z:
                continue
            x = res[m, c]
            big = np.isfinite(x) & (np.abs(x) > SIGNIFICANT_Z)
            k = int(np.nanargmax(np.abs(x)))
            out.append({"recording": int(r), "channel": ch, "rms": float(z[c] * closure.floor[c]),
                        "floor": float(closure.floor[c]), "z": float(z[c]), "worst_t_s": float(t[k]),
                        "worst": float(x[k] * closure.floor[c]),
                        "above_s": [float(t[big][0]), float(t[big][-1])] if big.any() else None,
                        "shape": "kinematic: the loaded sole moves under the model's forward kinematics (a foot "
                                 "sliding, or a kinematic error the library lacks)"})
    return out


# -- the dynamics' share -------------------------------------------------------------------------------------------
# The closure places a tilt within a few percent; the torques are far more sensitive to it (a hip axis 2 % short of
# its true tilt of 0.078 rad left the base's roll moment at 5.8 floors, the true one at 1). So each named parameter
# also enters the dynamics' selection as a correction with its linear signature: chosen there, it is fitted jointly
# with the dynamic effects (not against them) and added to the closure's value.
CORRECTION_BOUND = {"link_length": 0.02, "joint_axis": 0.02}    # |correction|: scale; rad


def correction_candidates(ds: Dataset, nominal: pin.Model, kinematic: list[Effect]) -> list[Candidate]:
    """One candidate per named kinematic effect: the dynamics' residual change per unit of its parameters (finite
    differences about the closure's estimate; the controller channels do not change)."""
    if not kinematic:
        return []
    out = []
    base = [evaluate(kinematic_model(nominal, kinematic), rec, seated=np.isin(lab, ["seated", "seat-off"]),
                     offsets=False, signatures=False).e for rec, lab in zip(ds.recordings, ds.labels)]
    for i, e in enumerate(kinematic):
        names = ["value"] + (["value_2"] if e.kind == "joint_axis" else [])
        cols = [np.zeros(ev.e.shape + (len(names),)) for ev in ds.evaluations]
        for k, key in enumerate(names):
            moved = list(kinematic)
            moved[i] = replace(e, **{key: float(getattr(e, key)) + FD_STEP})
            model = kinematic_model(nominal, moved)
            for r, (rec, lab) in enumerate(zip(ds.recordings, ds.labels)):
                ev = evaluate(model, rec, seated=np.isin(lab, ["seated", "seat-off"]), offsets=False,
                              signatures=False)
                cols[r][:, :ev.e.shape[1], k] = -(ev.e - base[r]) / FD_STEP   # the residual an error leaves
        bound = CORRECTION_BOUND[e.kind]
        out.append(Candidate(e.kind, e.location, [f"correction of {n}" for n in names], stack_rows(ds, cols),
                             plausible=lambda th, b=bound: None if np.all(np.abs(th) <= b) else
                             f"a correction past {b} of the closure's estimate", columns=cols))
    return out


def corrected(kinematic: list[Effect], chosen, say) -> list[Effect]:
    """The closure's kinematic effects with the dynamics' corrections (``chosen``: selected candidates of their
    kinds) added; one that comes out below its kind's ``SMALLEST`` is dropped."""
    out = [replace(e) for e in kinematic]
    for s in chosen:
        e = next(d for d in out if d.key == s.candidate.key)
        e.value += float(s.theta[0])
        if len(s.theta) > 1:
            e.value_2 += float(s.theta[1])
        se = np.sqrt(np.clip(np.diag(s.cov), 0.0, None))
        e.ci95 = 1.96 * float(se[0])
        if len(se) > 1:
            e.ci95_2 = 1.96 * float(se[1])
        e.refined = "by the dynamics"
    for e in [e for e in out if not _matters(e)]:
        say(f"  {e.key}: below the smallest error named once the dynamics refined it")
        out.remove(e)
    return out
