"""Write the answer key of the robots/ loaders: run at commit 38285f9, before the loaders became
uses of RobotModel.from_urdf, so the key comes from the hand-written loaders (test_robot.py)."""

import json
import sys
from pathlib import Path

import numpy as np
import pinocchio as pin
from dmpopt_robots import load_talos
from dmpopt_robots.biped import load_biped


def record(robot):
    out = {}
    for name in robot.__dataclass_fields__:
        value = getattr(robot, name)
        if name == "model":
            m = value
            out["model"] = {
                "name": m.name,
                "nq": m.nq,
                "nv": m.nv,
                "joints": list(m.names),
                "frames": [f.name for f in m.frames],
                "mass": float(pin.computeTotalMass(m)),
                "armature": np.array(m.armature).tolist(),
            }
        elif name == "source":
            out[name] = Path(value).name
        elif isinstance(value, np.ndarray):
            out[name] = value.tolist()
        elif name == "joint_groups":
            out[name] = {k: list(v) for k, v in value.items()}
        elif isinstance(value, tuple):
            out[name] = list(value)
        else:
            out[name] = value
    return out


key = {
    f"talos_{v}_{fb}": record(load_talos(v, fixed_base=fb))
    for v in ("full", "reduced")
    for fb in (False, True)
}
key["biped"] = record(load_biped())
Path(sys.argv[1]).write_text(json.dumps(key, indent=None, sort_keys=True) + "\n")
