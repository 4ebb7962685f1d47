"""Stand-ins for what the store reads of a campaign and its cases, shared by the store's test
files: a few case specs, a campaign, a row for a spec and a random trajectory."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from mbh._harness.model.trajectory import Trajectory


#: A small campaign ``mbh run`` can run (three fourbar cases of 0.2 s), for the store's end-to-end
#: tests.
RUNNABLE_CAMPAIGN = """
calibration = false
[t_end]
"*" = 0.2
[[group]]
scenarios = ["fourbar"]
methods = { inhouse = ["rk4+none"] }
dts = [1e-2, 5e-3, 2e-3]
"""


@dataclass(frozen=True)
class Spec:
    """The CaseSpec attributes the store reads (mbh._harness.run.spec.CaseSpec has more)."""

    scenario: str
    adapter: str
    method: str
    dt: float
    t_end: float

    @property
    def case_id(self) -> str:
        return f"{self.scenario}|{self.adapter}|{self.method}|{self.dt!r}|{self.t_end!r}"


@dataclass(frozen=True)
class Campaign:
    """The Campaign attributes the store reads."""

    name: str
    path: Path
    text: str
    cases: tuple


SPECS = (Spec("fourbar", "mujoco", "best", 0.001, 1.0),
         Spec("fourbar", "inhouse", "rk4+direct:proj_tol=1e-12", 0.01, 1.0),
         Spec("slider_crank", "pybullet", "default", 0.001, 0.5),
         Spec("slider_crank", "inhouse", "bdf4+baumgarte:alpha=5,beta=5", 0.0001, 0.5))


def campaign(name: str = "demo") -> Campaign:
    return Campaign(name, Path(f"campaigns/{name}.toml"), '# "<markup>" & ünïcode\n[x]\n',
                    SPECS)


def row_for(spec: Spec, **values) -> dict:
    base = {"case_id": spec.case_id, "scenario": spec.scenario, "adapter": spec.adapter,
            "method": spec.method, "dt": spec.dt, "t_end": spec.t_end, "status": "ok",
            "reason": "", "failure_time": None, "main_output_error": 1e-6, "wall_time_s": 1.0,
            "steps": 100}
    return {**base, **values}


def trajectory(n_samples: int = 3, n_bodies: int = 2, **kwargs) -> Trajectory:
    rng = np.random.default_rng(7)
    shape = (n_samples, n_bodies)
    return Trajectory(times=np.linspace(0.0, 0.02, n_samples),
                      position=rng.normal(size=(*shape, 3)),
                      quaternion=rng.normal(size=(*shape, 4)),
                      velocity=rng.normal(size=(*shape, 3)),
                      angular_velocity=rng.normal(size=(*shape, 3)), **kwargs)
