#!/usr/bin/env python3
"""Steps per second of MuJoCo on the catalogue arms, the peer of `cargo bench --bench step`.

Same robots (the catalogue URDFs, primitive geometry), same 1 ms step, same task: hold a
configuration under gravity with position servos on every joint. Self-collision is off on
both sides (workcell turns off a robot's self-contacts; MuJoCo's geoms get contype 0), and
MuJoCo steps in C++ through `mujoco.rollout`, so no Python loop is timed.

Needs `pip install mujoco==3.17.0`; run by scripts/bench-vs-mujoco.sh.
Prints one line per robot: name, steps/s, mujoco version, active contacts at the end.
"""

import os
import sys
import time

import mujoco
import numpy as np
from mujoco import rollout

HERE = os.path.dirname(os.path.abspath(__file__))
ROBOTS = {
    "ur5e_kinematics": [0.0, -1.2, 1.5, -1.9, -1.57, 0.0],
    "iiwa14_kinematics": [0.0, 0.6, 0.0, -1.4, 0.0, 0.8, 0.0],
}
STEPS = 20_000


def model_for(name, q_hold):
    path = os.path.join(HERE, "..", "robots", "urdf", name, f"{name}.urdf")
    spec = mujoco.MjSpec.from_file(path)
    spec.option.timestep = 0.001
    spec.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    for joint in spec.joints:
        act = spec.add_actuator()
        act.name = f"servo_{joint.name}"
        act.target = joint.name
        act.trntype = mujoco.mjtTrn.mjTRN_JOINT
        act.set_to_position(kp=2000.0, kv=100.0)
    for geom in spec.geoms:
        geom.contype = 0
        geom.conaffinity = 0
    model = spec.compile()
    data = mujoco.MjData(model)
    data.qpos[:] = q_hold
    data.ctrl[:] = q_hold
    mujoco.mj_forward(model, data)
    return model, data


def main():
    for name, q in ROBOTS.items():
        model, data = model_for(name, q)
        spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
        state = np.empty(mujoco.mj_stateSize(model, spec))
        mujoco.mj_getState(model, data, state, spec)
        control = np.array(q, dtype=float).reshape(1, 1, -1)
        rollout.rollout(model, data, state, control, nstep=1000)  # warm up
        best = 0.0
        for _ in range(5):
            start = time.perf_counter()
            rollout.rollout(model, data, state, control, nstep=STEPS)
            best = max(best, STEPS / (time.perf_counter() - start))
        print(f"{name} {best:.0f} {mujoco.__version__} {data.ncon}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
