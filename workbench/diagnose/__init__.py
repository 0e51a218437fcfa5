"""Mismatch diagnosis: locate where simulation and recording differ, name the missing
physics, model it and show the fit improve.

The method is split into parts (one concept per module):

* :mod:`.data` -- the recording checked, smoothed, differentiated; noise; replay mode;
* :mod:`.engine` -- compiled, re-anchorable replays (parameters as inputs);
* :mod:`.predict` -- short-horizon predictions and re-anchored closed-loop segments;
* :mod:`.witness` -- flow and force witnesses (the model's equations along the data);
* :mod:`.locate` -- operating regimes and time intervals of the mismatch;
* :mod:`.candidates` -- the effects of formats.md section 2 and wrong nominal values;
* :mod:`.refit` -- signature scan and least-squares refit of one candidate;
* :mod:`.explain` -- all candidates in parallel, ranked by evidence; the findings chosen;
* :mod:`.evidence` -- a finding's evidence sentence and confidence;
* :mod:`.polish` -- a finding's values refined by the grey-box estimator;
* :mod:`.health` -- failed replays (never a silent all-clear), the noise floor, and
  stick-slip hunting stretches (what a free-running replay cannot reproduce);
* :mod:`.replays` -- the recording replayed on a plant (fit before and after);
* :mod:`.nominal` -- the nominal plant against the recording (objective, regimes);
* :mod:`.joined` -- the objective of recordings with different signals joined (each
  predicted as alone, each signal compared where recorded);
* :mod:`.result` -- :class:`Finding`, :class:`Diagnosis` (JSON, summary, result set);
* :mod:`.blas` -- one BLAS thread while a diagnosis runs (its workers are processes);
* :mod:`.core` -- :func:`diagnose`: replay, locate, explain, augment, refit;
* :mod:`.report`, :mod:`.figures` -- the HTML/PDF report (``workbench diagnose`` is
  :mod:`workbench.cli.diagnose`, ``workbench bench diagnose`` :mod:`workbench.bench.diagnose`);
* :mod:`.synth` -- recordings of rigs with a concealed effect (tests, proof design;
  the diagnosis never imports it).

Examples
--------
Skipped here: a diagnosis takes 5-10 s (tests/test_diagnose*.py run it on synthetic
recordings, e.g. from :func:`.synth.record` written with ``case.write_nominal`` and
``rec.to_csv``):

>>> from workbench.diagnose import diagnose
>>> d = diagnose("plant.toml", "recording.csv")   # doctest: +SKIP
>>> print(d.summary())                            # doctest: +SKIP
>>> d.write("diagnosis/")                         # doctest: +SKIP
"""

from .candidates import Candidate, Free, candidates
from .core import Diagnosis, Finding, diagnose, replay
from .health import DiagnosisError
from .explain import Ranked

__all__ = ["diagnose", "Diagnosis", "Finding", "Ranked", "Candidate", "Free", "candidates",
           "replay", "DiagnosisError"]
