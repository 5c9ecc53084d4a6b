"""``pmdcid plan``: which experiments to record, and what each will tell.

:mod:`.profiles` generates the candidate inputs, :mod:`.fisher` the information each carries
about the parameters (sensitivities of the exact kernel at the model), :mod:`.design` chooses
the mix and lengths for a recording budget, :mod:`.effects` what the plan tells about each
catalogue effect, :mod:`.check` what logs a user already has leave undetermined, and
:mod:`.output` writes the files.
"""

from pmdcid.plan.design import Plan, Settings, plan_for_model
from pmdcid.plan.fisher import Drive, drive_of

__all__ = ["Drive", "Plan", "Settings", "drive_of", "plan_for_model"]
