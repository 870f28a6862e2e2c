"""Plan the test that identifies the car best, before anyone drives: `vehid design`. Start at `design_test`
(search.py); docs/design.md has the method and the JSON contract.

A test is a `Plan` (plan.py): the speed, the bump heights under the four corners, the bump's shape and length, the
record's duration and (optionally) which of the candidate sensors are mounted. Its merit (criterion.py) is the
Cramér–Rao bound of the configured identification on it, computed exactly as `vehid identify` computes it, reduced
to one number by `design.criterion` (`nre`, `d_optimal`, `worst`, `worst:<param>`).

Heights. The responses are linear in the road, so scaling every height by c scales the sensitivities by c. With
an absolute noise floor (noise.sigma) the Fisher information scales by c²; under Eq. 15 (noise.level) sigma scales
by c too and the information is unchanged; a mix of both is F_Eq15 + c² F_floor, never worse for a larger c. So
the highest corner always sits at `design.heights.max` and the design variables are the height ratios (space.py).

Modules, one concept each:

- plan.py: `Plan`, corner heights from the side/axle ratios, a plan written into a config;
- space.py: `Space`, the designed variables and their ranges, grids along one variable;
- criterion.py: `Evaluation`, the bound of a plan and its criterion;
- scoring.py: `Scorer`, candidates scored in parallel over the executor (bit-identical for any job count);
- optimum.py: differential evolution then coordinate sweeps, for fixed sensors;
- sensors.py: the sensor subset on the per-channel Fisher information (which adds up);
- profiles.py: `Profile`, the criterion along one variable (the figures' curves);
- proposals.py: `Proposal`, the cheapest single change that makes every unknown identifiable;
- verification.py: `Verification`, the `--verify` campaigns;
- checks.py: `check_design` (keyed errors) and the noise note;
- result.py: `DesignResult`, the factors computed once;
- search.py: `design_test`, which runs them in that order.
"""

from __future__ import annotations

from .checks import check_design, noise_note
from .criterion import Evaluation, criterion_value, evaluate
from .plan import Plan, apply_plan, configured_plan, corner_heights
from .profiles import Profile
from .proposals import Proposal
from .result import DesignResult
from .search import design_test
from .sensors import channel_information, choose_sensors
from .space import LABELS, VARIABLES, Space, design_space
from .verification import Verification

__all__ = [
    "LABELS",
    "VARIABLES",
    "DesignResult",
    "Evaluation",
    "Plan",
    "Profile",
    "Proposal",
    "Space",
    "Verification",
    "apply_plan",
    "channel_information",
    "check_design",
    "choose_sensors",
    "configured_plan",
    "corner_heights",
    "criterion_value",
    "design_space",
    "design_test",
    "evaluate",
    "noise_note",
]
