"""The model-gap workflow's augmented model file: the nominal links with the named masses merged, the joint and
sensor effects, and the same effects as a plant file's ``unmodeled`` section (:mod:`sit2stand.gap.workflow`, step 4).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pinocchio as pin
import yaml

from .effects import unmodeled_dict, unmodeled_from
from .validate import merged_model
from .workflow import GapResult


def augmented_model(result: GapResult, nominal: pin.Model) -> dict:
    """The augmented model file's content (see :mod:`sit2stand.gap.workflow`, step 4)."""
    effects = result.known + result.effects
    model = merged_model(nominal, effects)
    link_params = {model.names[j]: {"mass": float(model.inertias[j].mass),
                                    "com": [float(v) for v in model.inertias[j].lever]}
                   for j in range(1, model.njoints)}
    return {"nominal": result.model_source, "bags": result.bags, "verdict": result.verdict,
            "effects": effects, "links": link_params, "unmodeled": unmodeled_dict(unmodeled_from(effects))}


def write_augmented(result: GapResult, nominal: pin.Model, path: str | Path) -> dict:
    """Write :func:`augmented_model` as YAML to ``path``; the document written."""
    doc = augmented_model(result, nominal)
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    Path(path).write_text("# written by sit2stand gap: the nominal model plus the effects it named\n"
                          + yaml.safe_dump(plain_data(doc), sort_keys=False))
    return doc


def plain_data(x):
    """``x`` with NumPy scalars and arrays as plain Python numbers and lists (for JSON)."""
    if isinstance(x, dict):
        return {str(k): plain_data(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [plain_data(v) for v in x]
    if isinstance(x, np.ndarray):
        return plain_data(x.tolist())
    if isinstance(x, (np.floating, float)):
        return float(x)
    if isinstance(x, (np.integer, int)) and not isinstance(x, bool):
        return int(x)
    return x
