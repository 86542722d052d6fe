"""Gratings, PPB ↔ cycles/degree, the PPB → α model and its emcee posterior.

The smartphone paper (``shared/seeds/smartphone-ward-brdf.txt``) estimates Ward α from the
finest square-wave grating, shown on the phone and seen reflected in the surface, that an
observer can still resolve. This module re-exports the pieces:

- :mod:`wardjax._gratings` — :class:`Display`, :class:`Viewing`, :func:`ppb_to_cpd`,
  :func:`cpd_to_ppb`, :func:`grating_image`, :func:`write_gratings`;
- :mod:`wardjax._alpha_model` — Table 1, the published per-lightness lines, the physical
  PPB→SD lines (:func:`physical_lines`), :class:`AlphaModel`;
- :mod:`wardjax._alpha_posterior` — the likelihood, priors and emcee sampler,
  :class:`AlphaPosterior`, :class:`NotConvergedError`;
- :mod:`wardjax._smartphone` — :func:`fit_smartphone`, the whole method on one surface.
"""

from ._alpha_model import AlphaModel as AlphaModel
from ._alpha_model import PhysicalLines as PhysicalLines
from ._alpha_model import lightness_from_rho_d as lightness_from_rho_d
from ._alpha_model import load_table1 as load_table1
from ._alpha_model import physical_lines as physical_lines
from ._alpha_posterior import AlphaPosterior as AlphaPosterior
from ._alpha_posterior import AlphaPosteriorBatch as AlphaPosteriorBatch
from ._alpha_posterior import NotConvergedError as NotConvergedError
from ._alpha_posterior import log_prob_numpy as log_prob_numpy
from ._alpha_posterior import simulate_observers as simulate_observers
from ._gratings import Display as Display
from ._gratings import Viewing as Viewing
from ._gratings import cpd_to_ppb as cpd_to_ppb
from ._gratings import grating_image as grating_image
from ._gratings import load_display as load_display
from ._gratings import load_viewing as load_viewing
from ._gratings import ppb_to_cpd as ppb_to_cpd
from ._gratings import write_gratings as write_gratings
from ._smartphone import fit_smartphone as fit_smartphone

__all__ = [
    "AlphaModel",
    "AlphaPosterior",
    "AlphaPosteriorBatch",
    "Display",
    "NotConvergedError",
    "PhysicalLines",
    "Viewing",
    "cpd_to_ppb",
    "fit_smartphone",
    "grating_image",
    "lightness_from_rho_d",
    "load_display",
    "load_table1",
    "load_viewing",
    "log_prob_numpy",
    "physical_lines",
    "ppb_to_cpd",
    "simulate_observers",
    "write_gratings",
]
