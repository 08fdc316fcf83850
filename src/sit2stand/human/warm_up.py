"""A dry run of the streaming COM estimator, made while the node waits for the capture.

As for the retargeter (:mod:`sit2stand.retarget.warm_up`): the stream's first frames are also the first calls of the
skeleton fit, the causal and centred windows, the support rule and the scaling rows, and the first mass re-solve
comes after a frame's COM, before the next frame. :func:`warm_up` runs them all on a synthetic rise of a human of
the subject's size (:func:`~sit2stand.human.synth.warm_up_config`) through an estimator of its own, made as the
node makes its one, and throws it away.
"""

from __future__ import annotations

import time

from ..io.messages import reorder_markers
from .com_stream import StreamingComEstimator
from .skeleton import Subject
from .synth import synthesize, warm_up_config


def warm_up(subject: Subject, marker_names: list[str], **estimator) -> float:
    """Stream the synthetic rise (its Plug-in-Gait markers put in ``marker_names``' order: those it lacks unseen)
    and its plates through ``StreamingComEstimator(subject, marker_names, **estimator)``, then re-solve the masses
    once; returns how long it took [s].

    Raises:
        ValueError: the estimator cannot take the synthetic human (too few of its markers, units): the node goes on
            without a dry run.
    """
    began = time.perf_counter()
    demo = synthesize(warm_up_config(height_m=subject.height_m, mass_kg=subject.mass_kg, sex=subject.sex))
    est = StreamingComEstimator(subject, marker_names, **{**estimator, "rate_hz": 100.0, "defer_rescale": True})
    for k, t_s in enumerate(demo.marker_t_s):
        for plate in demo.plates:
            est.add_plate_samples(plate.name, plate.t_s[k:k + 1], plate.force_n[k:k + 1],
                                  plate.moment_origin_nm[k:k + 1])
        positions, valid = reorder_markers(demo.marker_names, demo.markers_m[k], demo.marker_valid[k], marker_names)
        est.process_delayed(est.update(float(t_s), positions, valid, defer_delayed=True))
    est.rescale()
    return time.perf_counter() - began
