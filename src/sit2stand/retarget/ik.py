"""Per-frame inverse kinematics with the COM as a hard constraint and markers as soft tasks (Mistry et al. 2010).

Each frame solves, by damped Gauss-Newton steps on the configuration q (Pinocchio, floating base),

    minimise    sum_k w_k || p_k(q) - t_k ||^2  +  mu || q (-) q_ref ||^2        (markers soft, posture prior)
    subject to  c(q)[axes] = c_target[axes]                                      (COM: hard equality)
                X_sole(q) = X_sole_target   for both feet                       (feet fixed: hard, 6-D each)
                q_min <= q <= q_max,  |q_dot| dt <= v_max dt                      (joint and velocity limits)

with one dense QP (proxsuite) per step in the tangent step dq:
``min 1/2 dq' H dq + g' dq  s.t.  A dq = b,  l <= dq <= u`` built from the frame, COM and sole Jacobians.
Iterations are warm-started from the previous frame's solution. If the COM target cannot be met with the feet
fixed and within limits, the COM is made a heavily weighted soft task instead, and the frame is flagged infeasible;
the returned q always respects the joint limits and is finite.

Units SI; frames by Pinocchio frame id; positions in the world frame (REP-103).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin
import proxsuite   # at import (~0.1 s): a node imports this before its stream starts

from ..kinematics import PointJacobians, positions


@dataclass
class IkResult:
    """One frame's solution and how good it is."""

    q: np.ndarray
    feasible: bool             # the COM equality (and the feet) could be met
    com_error_m: float         # |c(q) - c_target| on the constrained axes
    sole_error: float          # largest sole pose error (norm of the 6-D log)
    marker_rms_m: float        # RMS marker distance
    iterations: int
    step_norm: float           # size of the last Gauss-Newton step (small at a local optimum)
    kkt_dual_residual: float   # dual (stationarity) residual of the last QP
    seconds: float


class ComIk:
    """QP inverse kinematics with a hard COM constraint (see the module docstring).

    Args:
        model: Pinocchio model (free-flyer root) with the COM parameters to use (identified, or CAD).
        sole_frames: frame ids of the two soles, kept at their target placements.
        velocity_limit: joint speed limit [rad/s] (scalar or per joint, nv - 6).
        dt: frame period [s] (velocity limits become step bounds).
        posture_weight: mu, the pull toward ``q_ref`` (regularisation of what the markers do not fix); scalar or
            per tangent direction (nv; the base's six are ignored).
        damping: Levenberg-Marquardt damping on the step.
    """

    def __init__(self, model: pin.Model, sole_frames: list[int], velocity_limit: float | np.ndarray = 5.0,
                 dt: float = 0.01, posture_weight: float | np.ndarray = 1e-3, damping: float = 1e-6) -> None:
        self.model = model
        self.data = model.createData()
        self.soles = list(sole_frames)
        self.nv = model.nv
        self.dt = dt
        self.mu = np.broadcast_to(np.asarray(posture_weight, float), (model.nv,)).copy()
        self.mu[:6] = 0.0
        self.damping = damping
        self.v_max = np.broadcast_to(np.asarray(velocity_limit, float), (model.nv - 6,)).copy()
        self.q_lo = model.lowerPositionLimit[7:].copy()
        self.q_hi = model.upperPositionLimit[7:].copy()
        self._proxsuite = proxsuite
        self._qp: dict[tuple[int, int], object] = {}
        self.eps_abs = 1e-9
        self.points = PointJacobians(model)

    def _solve_qp(self, H, g, A, b, lo, hi):
        key = (A.shape[0], len(lo))
        qp = self._qp.get(key)
        if qp is None:
            qp = self._proxsuite.proxqp.dense.QP(self.nv, A.shape[0], 0, True)
            qp.settings.eps_abs = self.eps_abs
            qp.settings.verbose = False
            qp.init(H, g, A, b, None, None, None, lo, hi)
            self._qp[key] = qp
        else:
            qp.update(H, g, A, b, None, None, None, lo, hi)
        qp.solve()
        status = str(qp.results.info.status)
        return qp.results.x.copy(), "SOLVED" in status and "INACCURATE" not in status, float(qp.results.info.dua_res)

    def solve(self, q0: np.ndarray, markers: list[tuple[int, np.ndarray, float]], com_target: np.ndarray,
              sole_targets: list[pin.SE3], q_ref: np.ndarray | None = None, com_axes: tuple[int, ...] = (0, 1, 2),
              q_prev: np.ndarray | None = None, max_iterations: int = 10, tol: float = 1e-7,
              base_xz: np.ndarray | None = None, base_weight: float | None = None,
              base_pitch_min: float | None = None) -> IkResult:
        """Solve one frame from ``q0``. ``markers``: (frame id, target position [m], weight) triples.
        ``q_prev``: the previous frame's configuration; the joint speed limits bound the motion from it (none for
        the first frame). ``base_xz``: hold the floating base's world x and z at these values [m] (e.g. the hips on
        a seat): two more equality rows, or, with ``base_weight``, a soft task of that weight. ``base_pitch_min``
        [rad]: the base may not pitch back beyond this (a pelvis on a seat cannot roll back about its hips)."""
        import time

        t0 = time.perf_counter()
        model, data, nv = self.model, self.data, self.nv
        q = q0.copy()
        q_ref = q0 if q_ref is None else q_ref
        axes = list(com_axes)
        fids = [int(m[0]) for m in markers]
        targets = np.array([m[1] for m in markers], float).reshape(-1, 3)
        w = np.array([m[2] for m in markers], float)
        feasible, dua = True, 0.0
        step = np.inf
        it = 0
        for it in range(1, max_iterations + 1):
            pin.computeJointJacobians(model, data, q)
            pin.updateFramePlacements(model, data)
            Jc = pin.jacobianCenterOfMass(model, data, False)
            com = data.com[0].copy()
            # markers: sum w ||J dq + e||^2
            P, J = self.points(data, fids)
            Jr = J.reshape(-1, nv)
            wr = np.repeat(w, 3)
            H = (Jr.T * wr) @ Jr
            g = Jr.T @ (wr * (P - targets).ravel())
            post = pin.difference(model, q_ref, q)
            post[:6] = 0.0
            H[np.diag_indices(nv)] += self.mu + self.damping
            g += self.mu * post
            # feet: J_sole dq = -log(X_target^-1 X), COM: J_com dq = c* - c
            rows, rhs = [], []
            for fid, target in zip(self.soles, sole_targets):
                err = pin.log6(target.actInv(data.oMf[fid])).vector
                rows.append(pin.getFrameJacobian(model, data, fid, pin.LOCAL))
                rhs.append(-err)
            if base_xz is not None:     # base linear velocity is in the base frame: world rows are R[[0, 2]]
                rb = np.zeros((2, nv))
                rb[:, :3] = data.oMi[1].rotation[[0, 2]]
                eb = (np.asarray(base_xz, float) - q[:3])[[0, 2]]
                if base_weight is None:
                    rows.append(rb)
                    rhs.append(eb)
                else:
                    H += base_weight * rb.T @ rb
                    g -= base_weight * rb.T @ eb
            A_feet, b_feet = np.vstack(rows), np.concatenate(rhs)
            A = np.vstack([A_feet, Jc[axes]])
            b = np.concatenate([b_feet, (com_target - com)[axes]])
            lo = np.full(nv, -1e20)
            hi = np.full(nv, 1e20)
            qj = q[7:]
            lo[6:], hi[6:] = self.q_lo - qj, self.q_hi - qj
            if q_prev is not None:     # speed limits: from the previous frame, over all of this frame's iterations
                lo[6:] = np.maximum(lo[6:], q_prev[7:] - self.v_max * self.dt - qj)
                hi[6:] = np.minimum(hi[6:], q_prev[7:] + self.v_max * self.dt - qj)
            if base_pitch_min is not None:
                R = data.oMi[1].rotation
                lo[4] = min(0.0, base_pitch_min - np.arctan2(R[0, 2], R[2, 2]))
            lo[6:] = np.minimum(lo[6:], 0.0)   # a configuration just past a limit may always move back inside
            hi[6:] = np.maximum(hi[6:], 0.0)
            dq, ok, dua = self._solve_qp(H, g, A, b, lo, hi)
            if not ok:
                # COM infeasible with the feet fixed and the limits: COM as a heavily weighted soft task
                feasible = False
                Hs = H + 1e4 * Jc[axes].T @ Jc[axes]
                gs = g - 1e4 * Jc[axes].T @ (com_target - com)[axes]
                dq, ok, dua = self._solve_qp(Hs, gs, A_feet, b_feet, lo, hi)
                if not ok:     # not even the feet: everything soft; the box alone is always feasible (0 is inside)
                    Hs += 1e6 * A_feet.T @ A_feet
                    gs -= 1e6 * A_feet.T @ b_feet
                    dq, ok, dua = self._solve_qp(Hs, gs, np.zeros((0, nv)), np.zeros(0), lo, hi)
                    if not ok:
                        dq = np.zeros(nv)
            q = pin.integrate(model, q, dq)
            q[7:] = np.clip(q[7:], self.q_lo, self.q_hi)      # exact limits, whatever the QP's tolerance
            if q_prev is not None:
                q[7:] = np.clip(q[7:], q_prev[7:] - self.v_max * self.dt, q_prev[7:] + self.v_max * self.dt)
            step = float(np.linalg.norm(dq))
            if step < tol:
                break
        if not np.all(np.isfinite(q)):
            raise FloatingPointError("IK produced a non-finite configuration")
        pin.framesForwardKinematics(model, data, q)        # the result's errors (no Jacobians needed)
        com = pin.centerOfMass(model, data, q, False)
        marker_sq = np.sum((positions(data, fids) - targets) ** 2, axis=1)
        sole_err = max(np.linalg.norm(pin.log6(t.actInv(data.oMf[f])).vector) for f, t in zip(self.soles, sole_targets))
        com_err = float(np.linalg.norm((com - com_target)[axes]))
        return IkResult(q, feasible and com_err < 1e-3, com_err, float(sole_err),
                        float(np.sqrt(np.mean(marker_sq))) if len(marker_sq) else 0.0, it, step, dua,
                        time.perf_counter() - t0)
