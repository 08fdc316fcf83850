"""The model-gap workflow's data: recordings read, labelled by phase, with the nominal model evaluated along them,
and each channel's noise floor from the residual's fast part.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pinocchio as pin

from ..dynamics import savgol_series
from ..errors import Sit2StandError
from ..robot.model import DEFAULT_ROBOT
from ..robot.profile import profile_of
from .control import ControlLaw, control_law
from .recording import Recording, read_recording
from .residuals import Evaluation, evaluate

MOVING_RADPS = 0.05          # RMS speed above which a joint's friction can be seen
FLOOR_WINDOW_S = 1.0         # the residual's slow part (any physical effect) is its Savitzky-Golay fit over this


class GapError(Sit2StandError, ValueError):
    """Input the workflow cannot use; the message names the file."""



# -- phases -----------------------------------------------------------------------------------------------------------
def phases(rec: Recording) -> tuple[np.ndarray, dict]:
    """Phase label per sample and the events found: a rise from a chair (the feet carry under 90 % of the final
    standing load, then all of it, and the pelvis ends >= 15 cm higher) gives seated / seat-off / rising / standing;
    otherwise moving / still (joint speed) or static (held postures)."""
    n = len(rec)
    if rec.static:
        return np.full(n, "static", dtype=object), {}
    fz = rec.feet_force_z_n
    z = rec.base_pose[:, 2]
    speed = np.sqrt(np.mean(rec.qd ** 2, axis=1))
    labels = np.where(speed > MOVING_RADPS, "moving", "still").astype(object)
    tail = max(5, n // 5)
    if z[-tail:].mean() - z[:tail].mean() < 0.15:
        return labels, {}
    load = fz / max(np.median(fz[-tail:]), 1e-9)
    dt = float(np.median(np.diff(rec.t_s)))
    hold = max(1, int(round(0.2 / dt)))
    above = load >= 0.95
    k_so = next((k for k in range(n - hold) if above[k:k + hold].all()), None)
    if k_so is None or load[:max(k_so, 1)].min() > 0.9:
        return labels, {}
    t_so = float(rec.t_s[k_so])
    z_final = np.median(z[-tail:])
    k_up = next((k for k in range(k_so, n) if z[k] >= z_final - 0.01), n - 1)
    t = rec.t_s
    labels = np.full(n, "rising", dtype=object)
    labels[t < t_so - 0.25] = "seated"
    labels[np.abs(t - t_so) <= 0.25] = "seat-off"
    labels[t >= t[k_up]] = "standing"
    return labels, {"seat_off_s": t_so, "standing_s": float(t[k_up])}


FALLEN_ABOVE_FALL_M = 0.10
"""A recording counts as fallen from a pelvis this far above the robot's fall height (its profile's; TALOS: 0.45 m)."""


def fallen(rec: Recording, fall_height_m: float) -> np.ndarray:
    """Samples after the robot fell (pelvis below ``fall_height_m`` + ``FALLEN_ABOVE_FALL_M`` or the base tilted
    past 60 degrees)."""
    w = rec.base_pose[:, 3:7]
    tilt = 2 * np.arccos(np.clip(np.sqrt(w[:, 0] ** 2 + w[:, 3] ** 2), 0, 1))
    bad = (rec.base_pose[:, 2] < fall_height_m + FALLEN_ABOVE_FALL_M) | (tilt > np.radians(60))
    return np.maximum.accumulate(bad)


# -- data --------------------------------------------------------------------------------------------------------------
@dataclass
class Dataset:
    """Recordings with their evaluation, phases and noise floors."""

    recordings: list[Recording]
    evaluations: list[Evaluation]
    labels: list[np.ndarray]
    events: list[dict]
    floors: list[np.ndarray] = field(default_factory=list)     # per recording: (C,) noise floor per channel
    notes: list[str] = field(default_factory=list)
    robot: str = DEFAULT_ROBOT                                 # the robot's profile name

    @property
    def channels(self) -> list[str]:
        """The residual channels (base rows, joint torques, controller channels)."""
        return self.evaluations[0].channels

    @property
    def joint_names(self) -> list[str]:
        """The recordings' joints (plant order)."""
        return self.recordings[0].joint_names


def load_dataset(bags: list[str | Path], model: pin.Model, rate_hz: float = 50.0, progress=None,
                 controller_params: dict | None = None) -> Dataset:
    """Read each bag (what follows a fall left out), label its phases and evaluate ``model`` along it; controller
    channels for all recordings when any has commands (``controller_params``: the controller's links, None: CAD)."""
    recs, labels, events, notes = [], [], [], []
    profile = profile_of(model)
    for bag in bags:
        rec = read_recording(bag, model, rate_hz=rate_hz)
        down = fallen(rec, profile.fall_pelvis_height_m)
        if down.any():
            notes.append(f"{bag}: the robot fell at {rec.t_s[np.argmax(down)]:.2f} s; the samples after are left out")
            rec = rec.subset(~down)
        if recs and rec.joint_names != recs[0].joint_names:
            raise GapError(f"{bag}: joints differ from {recs[0].source}'s")
        lab, ev_info = phases(rec)
        if progress:
            progress(f"  {bag}: {len(rec)} samples ({'static postures' if rec.static else 'run'}); evaluating the "
                     "model along them")
        recs.append(rec)
        labels.append(lab)
        events.append(ev_info)
        notes.extend(rec.notes)
    ds = Dataset(recs, [], labels, events, notes=notes, robot=profile.name)
    evaluate_all(ds, model, controller_params)
    return ds


def evaluate_all(ds: Dataset, model: pin.Model, controller_params: dict | None = None) -> None:
    """(Re)evaluate ``model`` along every recording of ``ds``, with the controller channels (see load_dataset)."""
    ds.evaluations = []
    for rec, lab in zip(ds.recordings, ds.labels):
        ev = evaluate(model, rec, seated=np.isin(lab, ["seated", "seat-off"]))
        law = control_law(rec, controller_params, robot=ds.robot)
        if law is not None:
            ev.add_control(law, rec.tau, rec.joint_names)
        ds.evaluations.append(ev)
    if any(ev.ctrl_law is not None for ev in ds.evaluations):   # one channel layout: no controller rows where none
        for rec, ev in zip(ds.recordings, ds.evaluations):
            if ev.ctrl_law is None:
                ev.add_control(ControlLaw.absent(*rec.tau.shape), rec.tau, rec.joint_names)


def fast_part_floor(e: np.ndarray, valid: np.ndarray, t_s: np.ndarray) -> np.ndarray:
    """(C,) robust scale of each channel's residual minus its slow part (Savitzky-Golay over FLOOR_WINDOW_S)."""
    dt = float(np.median(np.diff(t_s)))
    w = max(5, int(round(FLOOR_WINDOW_S / dt)) | 1)
    out = np.zeros(e.shape[1])
    for c in range(e.shape[1]):
        x = e[valid[:, c], c]
        if len(x) <= w:
            out[c] = np.nan
            continue
        fast = x - savgol_series(x, w, 2, 0)
        out[c] = 1.4826 * np.median(np.abs(fast - np.median(fast)))
    return out
