"""The report's inputs checked before a notebook starts: one line naming the file and the field.

What the report reads of each finished capture (``<name>/`` in the folder of fits):

* ``params.json``: schema ``wardjax.params/1``; ``method``, ``model``,
  ``normalization`` as text; ``params`` and ``stderr`` each holding ``rho_d``
  (3 numbers), ``rho_s`` (1 or 3), ``alpha_x``, ``alpha_y`` (finite numbers:
  the report prints each; every ``stderr`` ≥ 0); ``fit`` a table whose optional
  ``status`` is text, ``reduced_chi2`` a number, ``weighted`` a boolean,
  ``covariance.parameters`` names of shared parameters, ``diagnostics.errors``
  the 1-σ of each by each error model, ``diagnostics.residuals`` the RMS
  residual (sr⁻¹ and relative), ``posterior`` the α median, intervals, acceptance and τ;
* ``residuals.npz`` (optional): ``f_r`` and ``model`` of one ``(h, w, 3)``
  shape, ``binning`` a whole number ≥ 1, ``origin`` two whole numbers;
* ``posterior.npz`` (optional): ``alpha`` (and any other chain) of one
  ``(steps, walkers)`` shape, finite and not constant; ``thin`` a whole number ≥ 1;
* ``texture.json`` (optional): a texture description
  :meth:`~wardjax.TextureModel.load` reads; ``rho_d.tif`` (optional): a float image;
* ``report.json`` (optional, from ``wardjax diagnose``): ``gap`` numbers and
  ``found`` names.

Each file is also held to :data:`MAX_INPUT_BYTES` before it is read.
"""

from __future__ import annotations

import json
import zipfile
from pathlib import Path
from typing import Annotated, Any, Literal

import numpy as np
import pydantic
from pydantic import BaseModel, ConfigDict, Field, Strict

from .._rules import shorten
from ..capture._errors import pydantic_error

__all__ = ["MAX_INPUT_BYTES", "validate_fit_folder", "validate_fits_dir"]

# The largest file the report reads (params.json, an .npz, texture.json): a fit writes a few MiB at most.
MAX_INPUT_BYTES = 1 << 30

# Strict: a JSON boolean is not a number (lax pydantic reads ``true`` as 1.0); integers are numbers.
_Num = Annotated[float, Strict(), Field(allow_inf_nan=False)]
_Err = Annotated[float, Strict(), Field(ge=0, allow_inf_nan=False)]


class _Open(BaseModel):
    model_config = ConfigDict(extra="allow")


class _Params(_Open):
    rho_d: tuple[_Num, _Num, _Num]
    rho_s: _Num | tuple[_Num, _Num, _Num]
    alpha_x: _Num
    alpha_y: _Num


class _Stderr(_Open):
    rho_d: tuple[_Err, _Err, _Err]
    rho_s: _Err | tuple[_Err, _Err, _Err]
    alpha_x: _Err
    alpha_y: _Err


class _Posterior(_Open):
    alpha_median: _Num
    alpha_interval_68: tuple[_Num, _Num]
    alpha_interval_95: tuple[_Num, _Num]
    acceptance: Annotated[_Num, Field(ge=0, le=1)]
    autocorrelation_time: Annotated[_Num, Field(gt=0)]
    n_steps: Annotated[int, Strict(), Field(ge=1)] | None = None
    n_walkers: Annotated[int, Strict(), Field(ge=1)] | None = None
    effective_samples: _Err | None = None

    @pydantic.model_validator(mode="after")
    def _chain_length_whole(self):
        if self.n_steps is not None and (self.n_walkers is None or self.effective_samples is None):
            raise ValueError("fit.posterior: n_steps needs n_walkers and effective_samples beside it")
        return self


# The shared parameters a scanline fit's covariance may name (``alpha``: the isotropic α).
_SHARED = Literal["rho_s", "alpha", "alpha_x", "alpha_y"]


class _Covariance(_Open):
    parameters: list[_SHARED]


class _Errors(_Open):
    """``fit.diagnostics.errors``: 1-σ of the shared parameters by error model, in ``covariance.parameters`` order."""

    reported: str | None = None
    texture_field: list[_Err]
    scanline_sandwich: list[_Err]
    model: list[_Err]


class _Residuals(_Open):
    """``fit.diagnostics.residuals``: RMS of measured − fitted f_r (sr⁻¹) and as a share of the mean f_r."""

    rms: _Err
    relative_rms: Annotated[float, Strict(), Field(ge=0)]  # NaN where the mean f_r is 0


class _Diagnostics(_Open):
    errors: _Errors | None = None
    residuals: _Residuals | None = None


class _Fit(_Open):
    status: str | None = None
    reduced_chi2: _Num | None = None
    weighted: Annotated[bool, Strict()] | None = None
    covariance: _Covariance | None = None
    diagnostics: _Diagnostics | None = None
    posterior: _Posterior | None = None


class _ParamsFile(_Open):
    @pydantic.model_validator(mode="after")
    def _errors_match_names(self):
        cov, diag = self.fit.covariance, self.fit.diagnostics
        errors = diag.errors if diag is not None else None
        if cov is None or errors is None:
            return self
        for key in ("texture_field", "scanline_sandwich", "model"):
            values = getattr(errors, key)
            if values is not None and len(values) != len(cov.parameters):
                raise ValueError(
                    f"fit.diagnostics.errors.{key} holds {len(values)} values for the "
                    f"{len(cov.parameters)} parameters of fit.covariance.parameters"
                )
        return self

    schema_: str = Field(alias="schema", pattern=r"^wardjax\.params/1$")
    method: str
    model: str
    normalization: str
    params: _Params
    stderr: _Stderr
    fit: _Fit


class _DiagnoseReport(_Open):
    gap: list[_Num]
    found: list[str] = []


def _read_bytes(path: Path) -> bytes:
    from .._files import check_regular_file

    check_regular_file(path)
    size = path.stat().st_size
    if size > MAX_INPUT_BYTES:
        raise ValueError(f"{path}: {size:,} bytes, more than the {MAX_INPUT_BYTES:,} a fit writes")
    return path.read_bytes()


def _json(path: Path) -> Any:
    try:
        return json.loads(_read_bytes(path).decode("utf-8"))
    except UnicodeDecodeError as e:
        raise ValueError(f"{path}: not UTF-8 text ({e.reason} at byte {e.start})") from None
    except json.JSONDecodeError as e:
        raise ValueError(f"{path}: not valid JSON ({e.msg}, line {e.lineno} column {e.colno})") from None
    except RecursionError:
        raise ValueError(f"{path}: not valid JSON (nested too deeply)") from None


def _model(path: Path, model: type[BaseModel], doc: Any) -> None:
    if not isinstance(doc, dict):
        raise ValueError(f"{path}: expected a JSON object at the top level, got {type(doc).__name__}")
    try:
        model.model_validate(doc)
    except pydantic.ValidationError as e:
        first = e.errors()[0]
        if not first["loc"]:  # a check across fields: its message names them
            raise ValueError(f"{path}: {shorten(first['msg'].removeprefix('Value error, '))}") from None
        raise ValueError(shorten(str(pydantic_error(e, str(path))).replace("schema_", "schema"))) from None


def _npz(path: Path) -> dict[str, np.ndarray]:
    import io

    try:
        with np.load(io.BytesIO(_read_bytes(path)), allow_pickle=False) as z:
            if not isinstance(z, np.lib.npyio.NpzFile):
                raise ValueError("not an .npz archive")
            return {k: z[k] for k in z.files}
    except (ValueError, OSError, EOFError, zipfile.BadZipFile, KeyError) as e:
        if str(path) in str(e):
            raise
        first = (str(e).strip().splitlines() or [type(e).__name__])[0]
        raise ValueError(f"{path}: not a readable .npz ({shorten(first, 160)})") from None


def _array(path: Path, z: dict, key: str, ndim: int) -> np.ndarray:
    if key not in z:
        raise ValueError(f"{path}: {key}: required array is missing (it holds {', '.join(sorted(z)) or 'none'})")
    a = z[key]
    if not np.issubdtype(a.dtype, np.number) or np.iscomplexobj(a) or a.ndim != ndim:
        raise ValueError(f"{path}: {key}: expected a real {ndim}-d array, got {a.dtype} of shape {a.shape}")
    return a


def _whole(path: Path, z: dict, key: str, n: int, low: int) -> None:
    a = _array(path, z, key, 0 if n == 1 else 1)
    if a.size != n or not np.issubdtype(a.dtype, np.integer) or np.any(a < low):
        raise ValueError(f"{path}: {key}: expected {n} whole number(s) ≥ {low}, got {shorten(str(a.tolist()), 80)}")


def _residuals(path: Path) -> None:
    z = _npz(path)
    f_r, model = _array(path, z, "f_r", 3), _array(path, z, "model", 3)
    if f_r.shape != model.shape or f_r.shape[-1] != 3 or 0 in f_r.shape:
        raise ValueError(f"{path}: model: shape {model.shape} does not match f_r {f_r.shape}, expected (h, w, 3)")
    _whole(path, z, "binning", 1, 1)
    _whole(path, z, "origin", 2, 0)


def _posterior(path: Path) -> None:
    z = _npz(path)
    alpha = _array(path, z, "alpha", 2)
    if min(alpha.shape) < 2:
        raise ValueError(f"{path}: alpha: expected at least 2 steps of 2 walkers, got shape {alpha.shape}")
    for key, a in z.items():
        if key == "thin":
            _whole(path, z, "thin", 1, 1)
        elif a.shape != alpha.shape or not np.issubdtype(a.dtype, np.floating):
            want = f"float chains of alpha's shape {alpha.shape}"
            raise ValueError(f"{path}: {key}: expected {want}, got {a.dtype} {a.shape}")
        elif not np.all(np.isfinite(a)):
            raise ValueError(f"{path}: {key}: holds non-finite values")
        elif a.max() == a.min():  # a corner plot needs a spread to draw
            raise ValueError(f"{path}: {key}: every sample is {a.flat[0]:g}; a chain has a spread")


def _tif(path: Path) -> None:
    from ..texture._images import _declared

    _read_bytes(path)
    shape, dtype = _declared(path, ".tif")
    if len(shape) not in (2, 3) or dtype.kind != "f":
        raise ValueError(f"{path}: expected a float (H, W[, C]) ρd image, got {dtype} {shape}")


def _texture(path: Path) -> None:
    from ..texture import TextureModel

    _read_bytes(path)
    TextureModel.load(path)


def validate_fit_folder(folder: Path) -> None:
    """Check every file the report reads in one capture's output ``folder``; ``ValueError`` naming file and field.

    Nothing is written; no kernel is started. See the module docstring for what each file must hold.
    """
    folder = Path(folder)
    pj = folder / "params.json"
    _model(pj, _ParamsFile, _json(pj))
    files = (
        ("residuals.npz", _residuals),
        ("posterior.npz", _posterior),
        ("texture.json", _texture),
        ("rho_d.tif", _tif),
    )
    for name, check in files:
        if (folder / name).exists() or (folder / name).is_symlink():
            check(folder / name)
    for rep in sorted(folder.glob("**/report.json")):
        _model(rep, _DiagnoseReport, _json(rep))


def validate_fits_dir(fits_dir) -> None:
    """:func:`validate_fit_folder` for every ``<name>/params.json`` under ``fits_dir`` (the report's input)."""
    root = Path(fits_dir)
    if root.is_dir():
        for pj in sorted(root.glob("*/params.json")):
            validate_fit_folder(pj.parent)
