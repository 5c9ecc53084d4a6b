"""``pmdcid fit-electrical``, ``fit-mechanical``, ``fit-nonlinear``: the paper's stages."""

from __future__ import annotations

import click

from pmdcid.cli import echo, main
from pmdcid.cli.options import (
    INPUT_FILE,
    controller_option,
    km_type,
    log_options,
    model_option,
)

#: --km within the bounds the model file accepts (a model the tool writes it must read back)
KM = km_type()
FORCE = click.option("--force", is_flag=True,
                     help="Write the model even when the logs look implausible (a unit left "
                          "unmapped, a saturated sensor): the refusal becomes a warning.")
LOGS = click.argument("logs", nargs=-1, required=True, type=INPUT_FILE,
                      metavar="LOG...")


def _names(allowed):
    def parse(ctx, param, value):
        if value is None:
            return None
        names = [v.strip() for v in value.split(",") if v.strip()]
        bad = [n for n in names if n not in allowed]
        if bad or not names:
            from pmdcid.io.escape import terminal

            raise click.BadParameter(f"{terminal(', '.join(bad)) or 'empty'}: choose among "
                                     f"{','.join(allowed)}")
        return names
    return parse


def _show(result, model_path):
    from pmdcid.cli.notes import echo_notes
    from pmdcid.fit.results import notes_of

    echo(result.table())
    echo_notes(notes_of(result))
    echo(f"updated {model_path}")


@main.command("fit-electrical")
@LOGS
@model_option()
@FORCE
@log_options
def fit_electrical_cmd(logs, model_path, force, mapping):
    """Blocked-rotor current steps -> R, L (the model file is created if missing)."""
    from pmdcid import api

    _show(api.fit_electrical(list(logs), model_path, mapping=mapping, update=True, force=force),
          model_path)


@main.command("fit-mechanical")
@LOGS
@model_option()
@click.option("--km", type=KM, default=None, metavar="X",
              help="Torque constant [N m/A] (datasheet); default: km from MODEL.")
@FORCE
@log_options
def fit_mechanical_cmd(logs, model_path, km, force, mapping):
    """Free-speed speed steps -> Kmot, tau_mot -> b, J (paper) and bv, bc (steady-speed line).

    Voltage steps need R, L and km (MODEL or --km); torque steps (a tau column) need nothing."""
    from pmdcid import api

    _show(api.fit_mechanical(list(logs), model_path, km=km, mapping=mapping, update=True,
                             force=force), model_path)


@main.command("fit-nonlinear")
@LOGS
@model_option()
@click.option("--signals", callback=_names(("omega", "theta")), default=None,
              metavar="omega,theta",
              help="Measured signals in the simulation error (default: the speed, measured or "
                   "derived from the angle; the angle only when no log has a speed).")
@click.option("--free", callback=_names(("J", "bv", "bc", "dz", "tau0")), default=None,
              metavar="J,bv,bc,dz",
              help="Parameters to fit (default J,bv,bc,dz; torque-driven logs J,bv,bc,tau0).")
@click.option("--dead-zone", is_flag=True,
              help="Torque-driven logs: fit the dead zone dz too (off by default).")
@click.option("--no-prior", is_flag=True,
              help="Use these logs alone (default: combine them with the estimates earlier "
                   "stages wrote, each a Gaussian prior of its standard error).")
@controller_option("Closed-loop logs: the controller that ran them (JSON file, or inline "
                   "type=PI,kp=..,ki=..,umax=..; docs/cli.md). The loop is simulated from the "
                   "logged reference and fitted; without it the logged output is fitted.")
@FORCE
@log_options
def fit_nonlinear_cmd(logs, model_path, signals, free, dead_zone, no_prior, controller, force,
                      mapping):
    """Triangular-input (or any rich) logs -> bc, bv, dz, J refined, by simulation error."""
    from pmdcid import api

    _show(api.fit_nonlinear(list(logs), model_path, free=free, signals=signals,
                            priors=not no_prior, controller=controller, dead_zone=dead_zone,
                            mapping=mapping, update=True, force=force), model_path)


@main.command("fit-inverse-dynamics")
@LOGS
@model_option()
@click.option("--as-published", is_flag=True,
              help="The EMPS authors' IDIM-LS exactly: every row kept, the held torque not "
                   "centred (default: rows near rest left out, torque centred on the hold).")
@click.option("--km", type=KM, default=None, metavar="X",
              help="Torque constant [N m/A] for voltage logs with a current column.")
@FORCE
@log_options
def fit_inverse_dynamics_cmd(logs, model_path, as_published, km, force, mapping):
    """Any logs with torque (or current) and angle or speed -> J, bv, bc, tau0 by inverse
    dynamics (linear least squares, instant; fit-nonlinear's start on torque-driven logs)."""
    from pmdcid import api

    _show(api.fit_inverse_dynamics(list(logs), model_path, km=km, as_published=as_published,
                                   mapping=mapping, update=True, force=force), model_path)
