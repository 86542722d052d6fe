"""The smartphone method: colour from a photo, Fresnel ρs, gratings, the PPB → α model and its posterior."""

from ._alpha_model import AlphaModel as AlphaModel
from ._alpha_model import lightness_from_rho_d as lightness_from_rho_d
from ._alpha_model import load_table1 as load_table1
from ._alpha_model import physical_lines as physical_lines
from ._alpha_model import PhysicalLines as PhysicalLines
from ._alpha_physical import alpha_posterior_physical as alpha_posterior_physical
from ._alpha_physical import physical_threshold_table as physical_threshold_table
from ._alpha_posterior import alpha_posterior as alpha_posterior
from ._alpha_posterior import alpha_posterior_batch as alpha_posterior_batch
from ._alpha_posterior import AlphaPosterior as AlphaPosterior
from ._alpha_posterior import AlphaPosteriorBatch as AlphaPosteriorBatch
from ._alpha_posterior import log_prob_numpy as log_prob_numpy
from ._alpha_posterior import NotConvergedError as NotConvergedError
from ._alpha_posterior import simulate_observers as simulate_observers
from ._color import decode_srgb as decode_srgb
from ._color import Decoding as Decoding
from ._color import DECODINGS as DECODINGS
from ._color import delta_E_CIE1976 as delta_E_CIE1976
from ._color import delta_E_CIE2000 as delta_E_CIE2000
from ._color import diffuse_from_srgb as diffuse_from_srgb
from ._color import diffuse_to_Lab as diffuse_to_Lab
from ._color import Lab_to_diffuse as Lab_to_diffuse
from ._color import luminance_from_rho_d as luminance_from_rho_d
from ._color import matrix_rgb_D65_to_E as matrix_rgb_D65_to_E
from ._color import validate_region as validate_region
from ._color import validate_rgb_image as validate_rgb_image
from ._colorchecker import CameraCorrection as CameraCorrection
from ._colorchecker import colorchecker_delta_E as colorchecker_delta_E
from ._colorchecker import colorchecker_held_out_delta_E as colorchecker_held_out_delta_E
from ._colorchecker import colorchecker_held_out_Lab as colorchecker_held_out_Lab
from ._colorchecker import COLORCHECKER_NAMES as COLORCHECKER_NAMES
from ._colorchecker import CORRECTION_METHODS as CORRECTION_METHODS
from ._colorchecker import colorchecker_patch_regions as colorchecker_patch_regions
from ._colorchecker import colorchecker_reference_Lab as colorchecker_reference_Lab
from ._colorchecker import colorchecker_rho_d as colorchecker_rho_d
from ._colorchecker import fit_camera_correction as fit_camera_correction
from ._colorchecker import simulate_colorchecker_photo as simulate_colorchecker_photo
from ._fresnel import fresnel_reflectance as fresnel_reflectance
from ._chart_error import ChartCorrection as ChartCorrection
from ._chart_error import chart_correction as chart_correction
from ._chart_error import rho_d_color_sigma as rho_d_color_sigma
from ._fresnel import metal_ior as metal_ior
from ._fresnel import METALS as METALS
from ._fresnel import specular_from_fresnel as specular_from_fresnel
from ._fresnel import specular_rgb_metal as specular_rgb_metal
from ._gratings import cpd_to_ppb as cpd_to_ppb
from ._gratings import grating_image as grating_image
from ._gratings import ppb_to_cpd as ppb_to_cpd
from ._gratings import write_gratings as write_gratings
from ._lobe_sd import lobe_sd_from_gonio as lobe_sd_from_gonio
from ._lobe_sd import lobe_sd_percent_error as lobe_sd_percent_error
from ._method import fit_smartphone as fit_smartphone
from ._threshold_model import CSF_METHODS as CSF_METHODS
from ._threshold_model import csf_cv_scatter as csf_cv_scatter
from ._threshold_model import csf_sensitivity as csf_sensitivity
from ._threshold_model import CSFFit as CSFFit
from ._threshold_model import CSF_CALIBRATIONS as CSF_CALIBRATIONS
from ._threshold_model import fit_csf_gratings as fit_csf_gratings
from ._threshold_model import fit_csf_modelfest as fit_csf_modelfest
from ._threshold_model import load_csf_gratings as load_csf_gratings
from ._threshold_model import load_modelfest as load_modelfest
from ._threshold_model import lobe_sd_from_threshold as lobe_sd_from_threshold
from ._threshold_model import screen_view_factor as screen_view_factor
from ._threshold_model import threshold_ppb as threshold_ppb
from ..capture import Display as Display
from ..capture import Viewing as Viewing
from ..capture import load_display as load_display
from ..capture import load_viewing as load_viewing

__all__ = [
    "AlphaModel",
    "lightness_from_rho_d",
    "load_table1",
    "physical_lines",
    "PhysicalLines",
    "alpha_posterior_physical",
    "physical_threshold_table",
    "alpha_posterior",
    "alpha_posterior_batch",
    "AlphaPosterior",
    "AlphaPosteriorBatch",
    "log_prob_numpy",
    "NotConvergedError",
    "simulate_observers",
    "decode_srgb",
    "Decoding",
    "DECODINGS",
    "delta_E_CIE1976",
    "delta_E_CIE2000",
    "diffuse_from_srgb",
    "diffuse_to_Lab",
    "Lab_to_diffuse",
    "luminance_from_rho_d",
    "matrix_rgb_D65_to_E",
    "validate_region",
    "validate_rgb_image",
    "CameraCorrection",
    "colorchecker_delta_E",
    "colorchecker_held_out_delta_E",
    "colorchecker_held_out_Lab",
    "ChartCorrection",
    "chart_correction",
    "rho_d_color_sigma",
    "COLORCHECKER_NAMES",
    "CORRECTION_METHODS",
    "colorchecker_patch_regions",
    "colorchecker_reference_Lab",
    "colorchecker_rho_d",
    "fit_camera_correction",
    "simulate_colorchecker_photo",
    "fresnel_reflectance",
    "metal_ior",
    "METALS",
    "specular_from_fresnel",
    "specular_rgb_metal",
    "cpd_to_ppb",
    "grating_image",
    "ppb_to_cpd",
    "write_gratings",
    "lobe_sd_from_gonio",
    "lobe_sd_percent_error",
    "fit_smartphone",
    "CSF_METHODS",
    "csf_cv_scatter",
    "csf_sensitivity",
    "CSFFit",
    "CSF_CALIBRATIONS",
    "fit_csf_gratings",
    "fit_csf_modelfest",
    "load_csf_gratings",
    "load_modelfest",
    "lobe_sd_from_threshold",
    "screen_view_factor",
    "threshold_ppb",
    "Display",
    "Viewing",
    "load_display",
    "load_viewing",
]
