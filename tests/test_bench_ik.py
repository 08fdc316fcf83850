"""sit2stand.bench.ik: the problems handed to mink and pink are the retargeter's, on the same kinematics."""

from pathlib import Path

import mujoco
import numpy as np
import pinocchio as pin

from sit2stand.bench.ik import SITE_PREFIX, frame_sites, recorded_problems
from sit2stand.vectors import wxyz_from_xyzw

BAG = Path(__file__).resolve().parents[1] / "bags" / "natural"


def test_every_frame_is_recorded_and_the_mjcf_sites_sit_on_the_pinocchio_frames():
    rt, fids, problems = recorded_problems(BAG, "talos")
    assert len(problems) == 391
    p = problems[200]
    assert p["targets"].shape == (len(fids), 3) and (p["weights"] > 0).sum() >= 30
    assert p["axes"] == (0, 1) and p["q0"].shape == (rt.model.nq,)
    frames = fids + list(rt.robot.sole_frames)
    mj = mujoco.MjModel.from_xml_string(frame_sites(rt.model, frames, "talos"))
    data, pdata = mujoco.MjData(mj), rt.model.createData()
    rng = np.random.default_rng(0)
    for q in (p["q0"], problems[-1]["q0"]):
        q = q.copy()
        q[7:] += rng.normal(0, 0.2, rt.model.nq - 7)
        data.qpos[:] = q
        data.qpos[3:7] = wxyz_from_xyzw(q[3:7])
        mujoco.mj_kinematics(mj, data)
        pin.framesForwardKinematics(rt.model, pdata, q)
        for fid in frames:
            site = mj.site(SITE_PREFIX + rt.model.frames[fid].name).id
            # within a micrometre: the MJCF text keeps ~7 digits
            assert np.allclose(data.site_xpos[site], pdata.oMf[fid].translation, atol=1e-6)
            assert np.allclose(data.site_xmat[site].reshape(3, 3), pdata.oMf[fid].rotation, atol=1e-6)
