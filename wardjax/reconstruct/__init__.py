"""Measured pixel values → BRDF values: the compiled band kernel, binning, the NumPy reference."""

from ._band import Reconstruction as Reconstruction
from ._band import reconstruct_capture as reconstruct_capture
from ._band import BandSetup as BandSetup
from ._band import prepare_bands as prepare_bands
from ._band import reconstruct_bands as reconstruct_bands
from ._bins import MIN_SCANLINE_SAMPLES as MIN_SCANLINE_SAMPLES
from ._bins import ScanlineBins as ScanlineBins
from ._bins import bin_scanlines as bin_scanlines
from ._bins import ScanlineBinner as ScanlineBinner
from ._bins import bin_layout as bin_layout
from ._bins import bin_sums as bin_sums
from ._reference import MaskReason as MaskReason
from ._reference import reconstruct_brdf as reconstruct_brdf
from ._reference import sample_bilinear as sample_bilinear
from ._checks import check_measured as check_measured
from ._checks import check_probe as check_probe
from ._checks import mask_counts as mask_counts

__all__ = [
    "Reconstruction",
    "reconstruct_capture",
    "BandSetup",
    "prepare_bands",
    "reconstruct_bands",
    "MIN_SCANLINE_SAMPLES",
    "ScanlineBins",
    "bin_scanlines",
    "ScanlineBinner",
    "bin_layout",
    "bin_sums",
    "MaskReason",
    "reconstruct_brdf",
    "sample_bilinear",
    "check_measured",
    "check_probe",
    "mask_counts",
]
