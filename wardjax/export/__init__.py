"""Materials out: the one ``params.json`` builder, Radiance, Mitsuba 3 and glTF materials, ρd on the sample plane,
a capture's output folder."""

from ._outputs import OUTPUT_FILES as OUTPUT_FILES
from ._outputs import scanline_figure_png as scanline_figure_png
from ._outputs import write_capture_outputs as write_capture_outputs
from ._outputs import write_smartphone_outputs as write_smartphone_outputs
from ._params import FIT_QUALITY_COLUMNS as FIT_QUALITY_COLUMNS
from ._params import PARAMS_SCHEMA as PARAMS_SCHEMA
from ._params import capture_fit_document as capture_fit_document
from ._params import fit_quality as fit_quality
from ._params import params_document as params_document
from ._params import smartphone_document as smartphone_document
from ._params import software_version as software_version
from ._radiance import RADIANCE_NORMALIZATION as RADIANCE_NORMALIZATION
from ._radiance import RADIANCE_PRIMARIES as RADIANCE_PRIMARIES
from ._radiance import radiance_material as radiance_material
from ._radiance import radiance_metal as radiance_metal
from ._radiance import radiance_rgb as radiance_rgb
from ._rectify import PlaneTexture as PlaneTexture
from ._rectify import rectify_rho_d as rectify_rho_d
from ._rectify import read_exr as read_exr
from ._rectify import write_exr as write_exr
from ._microfacet import MicrofacetFit as MicrofacetFit
from ._microfacet import fit_microfacet as fit_microfacet
from ._microfacet import microfacet_specular as microfacet_specular
from ._mitsuba import mitsuba_dict as mitsuba_dict
from ._mitsuba import mitsuba_xml as mitsuba_xml
from ._gltf import gltf_document as gltf_document
from ._gltf import gltf_material_brdf as gltf_material_brdf
from ._materials import material_exports as material_exports

__all__ = [
    "OUTPUT_FILES",
    "scanline_figure_png",
    "write_capture_outputs",
    "write_smartphone_outputs",
    "FIT_QUALITY_COLUMNS",
    "PARAMS_SCHEMA",
    "capture_fit_document",
    "fit_quality",
    "params_document",
    "smartphone_document",
    "software_version",
    "RADIANCE_NORMALIZATION",
    "RADIANCE_PRIMARIES",
    "radiance_material",
    "radiance_metal",
    "radiance_rgb",
    "PlaneTexture",
    "rectify_rho_d",
    "read_exr",
    "write_exr",
    "MicrofacetFit",
    "fit_microfacet",
    "microfacet_specular",
    "mitsuba_dict",
    "mitsuba_xml",
    "gltf_document",
    "gltf_material_brdf",
    "material_exports",
]
