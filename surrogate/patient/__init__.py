"""A new patient's model: the population model placed on the patient's liver (its boundary
condition), the liver's small-strain responses on its own mesh corrected with a few FE
simulations there, and distilled into a model of that one liver (the reduced basis,
:mod:`surrogate.basis`) that ``load_predictor``, the viewer and the manipulator use as any
other one-liver model.

    python -m surrogate adapt MODEL DATA --liver FILE --run OUT [--sims K] [--frame F] [--tune]

``DATA``: the patient's FE simulations with the model's boundary condition (``truth-scene``
then ``fem_sim generate``), and their small-strain responses with those of the drawn loads
(``fem_sim linear``, ``DATA/linear.h5``, :mod:`surrogate.linear_base`); ``make patient``
runs the four steps. The teacher's base is those responses (the exact linear elasticity of
the patient's mesh, with their second-order terms when ``fem_sim linear --order 2`` gave
them: :mod:`surrogate.linear_base`); a dataset without them falls back on the placed
population model.

With the population model of the base's rest (``--rest``), the rest's weight over the
base is first fitted to the K simulations (least squares, within [0, 1]: a liver whose own
base is already close takes less of it; :func:`fit_rest_weight`).

The correction (:class:`Correction`) is the residual of the FE fields against the base,
regressed on the load by kernel ridge regression (with ``tune``: against
that model with its network first fine-tuned on the K simulations, :mod:`surrogate.tuning`,
on the tuned network's out-of-fold residuals; docs/patient.md measures both). The kernel is a
Gaussian of the distance between the load points times a polynomial of the forces with no
constant term, ``g(x, x') (f.f' + beta (f.f')^2)``: a residual that vanishes with the force
and is nearly linear in it, as a hyperelastic liver's against a population model is for
small loads (against its own small-strain response, nearly quadratic), and that spreads
from a loaded point to its neighbours (a Gaussian, or an exponential with its heavier tail).
Two terms are added to it: the product of the base's fields for the two loads,
and that of what the K FE simulations say of each load by reciprocity (:class:`Sensors`:
by Maxwell-Betti, simulation k's first, nearly linear, load step gives the displacement at
its load point along its force that any other load causes there; so a load reads its
residual at the K load points, and the regression learns how the whole residual field
follows those K readings). The decay, length scale, ridge, beta and the weights of the two
added terms are chosen by cross-validation over the K simulations, grouped by simulation (a
held-out simulation's readings come from the others only); with fewer than
two, or when no setting beats the base on the held-out simulations, the base is kept
unchanged. The distillation takes loads drawn as the scene draws them (its eligible nodes,
uniform directions, its magnitude and load steps: ``fem_sim linear``'s drawn cases, or drawn
here without them), their fields from the corrected base, and trains the reduced basis on
them with the K FE fields.

The subpackage, one job a module: :mod:`~surrogate.patient.correction` (the kernel
regression and its cross-validation), :mod:`~surrogate.patient.teacher` (the base and the
correction fitted), :mod:`~surrogate.patient.distill` (the drawn loads and the student),
:mod:`~surrogate.patient.adapt` (the command), :mod:`~surrogate.patient.evaluation` (a
patient model against held-out FE simulations) and :mod:`~surrogate.patient.curve` (that
against K: ``surrogate evaluate-patient``).
"""

from surrogate.patient.adapt import adapt, adapted, used_simulations
from surrogate.patient.correction import Correction, Sensors, fit_correction
from surrogate.patient.distill import (
    STUDENT,
    SYNTHETIC,
    distilled,
    drawn_loads,
    student_config,
    with_cases,
)
from surrogate.patient.evaluation import (
    held_out_errors,
    load_predictor_of,
    predictor_fields,
    scratch_model,
)
from surrogate.patient.teacher import (
    Teacher,
    fit_rest_weight,
    fit_teacher,
    sample_fields,
    sims_samples,
)

__all__ = ["STUDENT", "SYNTHETIC", "Correction", "Sensors", "Teacher", "adapt", "adapted",
           "distilled", "drawn_loads", "fit_correction", "fit_rest_weight", "fit_teacher",
           "held_out_errors", "load_predictor_of", "predictor_fields", "sample_fields",
           "scratch_model", "sims_samples", "student_config", "used_simulations", "with_cases"]
