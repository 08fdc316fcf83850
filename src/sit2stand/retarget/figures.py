"""The figures of an offline retargeting run (``sit2stand retarget``): ``retarget.png``, the human's COM, its target
on the robot and the plan's COM and ZMP with the local time scale; and, simulated, ``timing.png``, the forward COM of
the human, the target, the plan and the robot at the human's timing. Units SI; forward is world x (REP-103)."""

from __future__ import annotations

from pathlib import Path

import matplotlib
import matplotlib.pyplot as plt
import numpy as np


def timing_figure(trial, com_h, frames, cmds, sim: np.ndarray, png: Path, summary: dict) -> None:
    """The forward COM at the human's timing: the human's (lab), the COM map's target, the plan's, the simulated
    robot's and its controller model's (world), each command at the human time it plays; and the local time scale.
    The simulation pulls one command per row, so row i is the robot when command i was sent."""
    matplotlib.use("Agg")
    t0 = trial.marker_t_s[0]
    t_frames = np.array([f.t_s for f in frames]) - t0
    t_cmd = t_frames[0] + np.array([c.t_plan_s for c in cmds])
    n = min(len(cmds), len(sim))
    fig, ax = plt.subplots(2, 1, figsize=(9, 6), sharex=True, gridspec_kw={"height_ratios": [3, 1]})
    ax[0].plot(trial.marker_t_s - t0, com_h[:, 0], color="0.6", label="human COM (lab)")
    ax[0].plot(t_frames, [f.com_target[0] for f in frames], label="human COM mapped onto the robot (target)")
    ax[0].plot(t_cmd, [c.com[0] for c in cmds], "--", label="plan COM")
    ax[0].plot(t_cmd[:n], sim[:n, 1], label="robot COM (simulated)")
    ax[0].plot(t_cmd[:n], sim[:n, 16], ":", color="0.3", lw=1,
               label="robot COM in its controller's model (off by the offset its feet measure)")
    ax[0].set_ylabel("forward [m]")
    ax[0].legend(fontsize=8)
    ax[0].set_title(f"{Path(summary['bag']).name}: at the human's timing; the robot took {summary['time_scale']:.2f}x "
                    f"the human's duration")
    ax[1].plot(t_cmd, [c.time_scale for c in cmds])
    ax[1].set_ylabel("local time scale")
    ax[1].set_xlabel("human time [s]")
    fig.tight_layout()
    fig.savefig(png, dpi=110)
    plt.close(fig)


def plan_figure(trial, com_h, frames, cmds, dt: float, png: Path, summary: dict) -> None:
    """The human's forward COM, its target on the robot and the IK's COM at the human's time; the plan's COM, ZMP
    and local time scale at the robot's."""
    matplotlib.use("Agg")
    t = trial.marker_t_s - trial.marker_t_s[0]
    t_frames = np.array([f.t_s for f in frames]) - trial.marker_t_s[0]      # lead-in frames before 0
    fig, ax = plt.subplots(2, 1, figsize=(9, 7), sharex=False)
    ax[0].plot(t, com_h[:, 0], label="human COM x")
    ax[0].plot(t_frames, [f.com_target[0] for f in frames], label="robot COM target x (mapped)")
    ax[0].plot(t_frames, [f.com[0] for f in frames], "--", label="robot IK COM x")
    so = summary.get("robot_seat_off_frame")
    if so is not None:
        ax[0].axvline(t_frames[so], color="k", lw=0.8, ls=":", label="robot seat-off")
    ax[0].set_ylabel("forward [m]")
    ax[0].set_xlabel("human time [s]")
    ax[0].legend(fontsize=8)
    tc = np.arange(len(cmds)) * dt
    ax[1].plot(tc, [c.com[0] for c in cmds], label="planned COM x")
    ax[1].plot(tc, [c.zmp[0] for c in cmds], label="planned ZMP x", alpha=0.7)
    ax[1].plot(tc, [c.time_scale / 10 for c in cmds], label="time scale / 10")
    ax[1].set_ylim(-0.3, 0.3)
    ax[1].set_xlabel("robot time [s]")
    ax[1].legend(fontsize=8)
    fig.suptitle(f"{Path(summary['bag']).name}: time scale {summary['time_scale']:.2f}, "
                 f"{summary['infeasible_frames']} infeasible IK frames"
                 + (f", {'stood up' if summary.get('stood_up') else 'fell'}" if "stood_up" in summary else ""))
    fig.tight_layout()
    fig.savefig(png, dpi=110)
    plt.close(fig)
