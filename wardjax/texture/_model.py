"""The parametric texture description and its file format (``.json`` or ``.npz``)."""

from __future__ import annotations

import io
import json
from pathlib import Path

import equinox as eqx
import numpy as np

from .._files import atomic_path, file_problem, write_json_atomic
from .._rules import one_line
from ._pyramid import (
    ORIENTATIONS,
)
from ._steerable import band_names

# A texture description is a few hundred KiB (quantile tables of up to 4097 entries per subband).
_MAX_MODEL_BYTES = 64 << 20

TEXTURE_FORMAT = "wardjax.texture"
TEXTURE_FORMAT_VERSION = 1
"""Version of the saved texture description; bumped when the file layout changes."""
# The largest pyramid and quantile table a description may hold (analysis makes at most 4 levels, 4097 quantiles).
MAX_HEIGHT = 16
MAX_QUANTILES = 4097
REGION_SOURCES = ("argument", "whole image", "largest valid rectangle")

# ================================================================== texture model


class TextureModel(eqx.Module):
    """The parametric texture of section 4.2: quantile tables of pixels and subbands, per decorrelated channel.

    Colour is handled as Heeger & Bergen suggest: RGB pixels ``x`` are
    decorrelated with a PCA, ``d = Vᵀ (x − μ)``, each channel of ``d`` is
    described and synthesised alone, and ``x = V d + μ`` maps back.

    Attributes
    ----------
    pca_mean
        ``(C,)`` channel mean ``μ`` of the analysed region.
    pca_basis
        ``(C, C)`` orthonormal ``V``; column ``k`` is principal axis ``k``
        (largest variance first, largest component positive).
    probabilities
        ``(Q,)`` the probabilities of every quantile table, increasing from 0
        to 1 (:func:`quantile_probabilities`: denser in the tails).
    pixel_quantiles
        ``(C, Q)`` quantiles of each decorrelated channel's pixels
        (``[:, 0]`` min, ``[:, -1]`` max).
    band_quantiles
        ``(C, B, Q)`` the same for each subband, ``B = 2 + 4 height``, in the
        order of :attr:`band_names`; subbands are taken from the periodic
        component of each channel, so image borders leave no trace.
    height
        Pyramid levels.
    rho_s
        ``(C,)`` specular reflectance: synthesis clamps ρd to ``[0, 1 − ρs]``.
    source_shape
        ``(H, W)`` of the image the texture was analysed from.
    region
        ``(y0, y1, x0, x1)`` the analysed rectangle (half-open, in pixels).
    region_source
        ``"argument"`` (given by the caller), ``"whole image"`` (no invalid
        pixels) or ``"largest valid rectangle"`` (the input held NaN).
    """

    pca_mean: np.ndarray
    pca_basis: np.ndarray
    probabilities: np.ndarray
    pixel_quantiles: np.ndarray
    band_quantiles: np.ndarray
    height: int = eqx.field(static=True)
    rho_s: np.ndarray
    source_shape: tuple[int, int] = eqx.field(static=True)
    region: tuple[int, int, int, int] = eqx.field(static=True)
    region_source: str = eqx.field(static=True)
    version: int = eqx.field(static=True, default=TEXTURE_FORMAT_VERSION)

    @property
    def channels(self) -> int:
        return int(self.pca_mean.shape[0])

    @property
    def n_quantiles(self) -> int:
        return int(self.pixel_quantiles.shape[-1])

    @property
    def band_names(self) -> tuple[str, ...]:
        return band_names(self.height)

    def describe_region(self) -> str:
        """One line saying which pixels were analysed and why."""
        y0, y1, x0, x1 = self.region
        return (
            f"rows {y0}:{y1}, columns {x0}:{x1} ({y1 - y0}x{x1 - x0} of {self.source_shape[0]}x"
            f"{self.source_shape[1]} pixels; {self.region_source})"
        )

    # ------------------------------------------------------------------ files

    def to_dict(self) -> dict:
        """Plain-Python form (lists and numbers) of the model; what :meth:`save` writes as JSON."""

        def rounded(a):  # float32 precision is all the quantiles carry
            return np.vectorize(lambda v: float(f"{v:.8g}"), otypes=[float])(np.asarray(a, np.float64)).tolist()

        return {
            "format": TEXTURE_FORMAT,
            "version": self.version,
            "height": self.height,
            "orientations": ORIENTATIONS,
            "channels": self.channels,
            "n_quantiles": self.n_quantiles,
            "source_shape": list(self.source_shape),
            "region": list(self.region),
            "region_source": self.region_source,
            "rho_s": rounded(self.rho_s),
            "pca_mean": np.asarray(self.pca_mean, np.float64).tolist(),
            "pca_basis": np.asarray(self.pca_basis, np.float64).tolist(),
            "probabilities": np.asarray(self.probabilities, np.float64).tolist(),
            "pixel_quantiles": rounded(self.pixel_quantiles),
            "band_names": list(self.band_names),
            "band_quantiles": rounded(self.band_quantiles),
        }

    @classmethod
    def from_dict(cls, d: dict, *, source: str = "texture description") -> TextureModel:
        """Validate and build a model from :meth:`to_dict`'s form; errors name ``source`` and the field.

        Every field is checked for its kind, shape and range, so that a model read from a file is one
        :func:`analyze_texture` could have made: ρs in [0, 1), an orthonormal PCA basis, the region inside
        the source image. Anything else is a ``ValueError`` naming ``source`` and the field, on one line.
        """

        def field(name):
            if name not in d:
                raise ValueError(f"{source}: missing field {name!r}")
            return d[name]

        def refuse(name, what):
            shown = repr(d[name])
            shown = shown if len(shown) <= 60 else shown[:57] + "..."
            raise ValueError(one_line(f"{source}: field {name!r} is {shown}, expected {what}"))

        fmt = field("format")
        if not isinstance(fmt, str) or fmt != TEXTURE_FORMAT:
            refuse("format", repr(TEXTURE_FORMAT))
        version = field("version")
        if isinstance(version, bool) or not isinstance(version, (int, np.integer)) or version != TEXTURE_FORMAT_VERSION:
            refuse("version", f"{TEXTURE_FORMAT_VERSION} (the version this wardjax reads)")

        def integer(name, lo, hi):
            v = field(name)
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or not lo <= v <= hi:
                refuse(name, f"an integer in [{lo}, {hi}]")
            return int(v)

        height, channels = integer("height", 0, MAX_HEIGHT), integer("channels", 1, 4)
        q = integer("n_quantiles", 2, MAX_QUANTILES)
        if integer("orientations", 1, 64) != ORIENTATIONS:
            refuse("orientations", str(ORIENTATIONS))
        n_bands = 2 + ORIENTATIONS * height

        def array(name, shape):
            value = field(name)
            try:
                a = np.asarray(value)
            except (TypeError, ValueError, OverflowError):
                a = None
            if a is None or a.dtype.kind not in "iuf":  # booleans, strings, mixed or ragged lists
                raise ValueError(f"{source}: field {name!r} is not an array of numbers")
            if a.shape != shape:
                raise ValueError(f"{source}: field {name!r} has shape {a.shape}, expected {shape}")
            a = a.astype(np.float64)
            if not np.isfinite(a).all():
                raise ValueError(f"{source}: field {name!r} holds NaN or inf")
            return a

        def pixels(name, n):
            a = array(name, (n,))
            if np.any(a != np.round(a)) or np.any(a < 0) or np.any(a > 2**31):
                refuse(name, f"{n} whole numbers of pixels")
            return tuple(int(v) for v in a)

        probs = array("probabilities", (q,))
        if probs[0] != 0 or probs[-1] != 1 or np.any(np.diff(probs) <= 0):
            raise ValueError(f"{source}: field 'probabilities' must increase from 0 to 1")
        pix = array("pixel_quantiles", (channels, q))
        bands = array("band_quantiles", (channels, n_bands, q))
        if np.any(np.diff(pix, axis=-1) < 0) or np.any(np.diff(bands, axis=-1) < 0):
            raise ValueError(f"{source}: quantile tables must be nondecreasing")
        names = field("band_names")
        if not isinstance(names, (list, tuple, np.ndarray)) or tuple(str(n) for n in names) != band_names(height):
            raise ValueError(f"{source}: field 'band_names' does not match height {height}")
        src_h, src_w = pixels("source_shape", 2)
        y0, y1, x0, x1 = pixels("region", 4)
        if not (0 <= y0 < y1 <= src_h and 0 <= x0 < x1 <= src_w):
            refuse("region", f"a non-empty rectangle inside the {src_h}x{src_w} source")
        rho_s = array("rho_s", (channels,))
        if np.any(rho_s < 0) or np.any(rho_s >= 1):
            refuse("rho_s", "values in [0, 1)")
        basis = array("pca_basis", (channels, channels))
        if not np.allclose(basis.T @ basis, np.eye(channels), atol=1e-6):
            raise ValueError(f"{source}: field 'pca_basis' is not orthonormal (the PCA's axes)")
        region_source = field("region_source")
        if not isinstance(region_source, str) or region_source not in REGION_SOURCES:
            refuse("region_source", " or ".join(repr(r) for r in REGION_SOURCES))
        return cls(
            pca_mean=array("pca_mean", (channels,)),
            pca_basis=basis,
            probabilities=probs,
            pixel_quantiles=pix,
            band_quantiles=bands,
            height=height,
            rho_s=rho_s,
            source_shape=(src_h, src_w),
            region=(y0, y1, x0, x1),
            region_source=str(region_source),
            version=int(version),
        )

    def save(self, path) -> Path:
        """Write the model to ``path``: ``.json`` (readable) or ``.npz``; atomically (temp file + rename)."""
        path = Path(path)
        d = self.to_dict()
        suffix = path.suffix.lower()
        if suffix == ".json":
            write_json_atomic(path, d, compact=True)
        elif suffix == ".npz":
            arrays = {k: np.asarray(v) for k, v in d.items()}
            with atomic_path(path) as tmp, open(tmp, "wb") as fh:
                # numpy's stub lets **kwds reach allow_pickle: bool; the keys are the model's field names.
                np.savez_compressed(fh, **arrays)  # pyright: ignore[reportArgumentType]
        else:
            raise ValueError(f"{path}: unknown texture file type {path.suffix!r}, expected .json or .npz")
        return path

    @classmethod
    def load(cls, path) -> TextureModel:
        """Read a model written by :meth:`save` (``.json`` or ``.npz``), checking format, version and shapes."""
        path = Path(path)
        if (problem := file_problem(path)) == "no such file":
            raise ValueError(f"{path}: no such texture file")
        if problem is not None:  # a FIFO or a device would be read without end
            raise ValueError(f"{path}: {problem}; expected a texture file (.json or .npz)")
        suffix = path.suffix.lower()
        if suffix not in (".json", ".npz"):
            raise ValueError(f"{path}: unknown texture file type {path.suffix!r}, expected .json or .npz")
        if path.stat().st_size > _MAX_MODEL_BYTES:
            raise ValueError(f"{path}: {path.stat().st_size:,} bytes, more than a texture description holds")
        try:
            data = path.read_bytes()
        except OSError as e:
            raise ValueError(f"{path}: cannot read ({e.strerror})") from None
        if suffix == ".json":
            try:
                d = json.loads(data.decode("utf-8"))
            except UnicodeDecodeError as e:
                raise ValueError(f"{path}: not valid JSON (not UTF-8 text at byte {e.start})") from None
            except (ValueError, RecursionError) as e:  # JSONDecodeError, a number too long, nesting too deep
                raise ValueError(one_line(f"{path}: not valid JSON ({str(e)[:120]})")) from None
            if not isinstance(d, dict):
                raise ValueError(f"{path}: expected a JSON object at top level")
        else:
            try:
                with np.load(io.BytesIO(data), allow_pickle=False) as z:
                    d = {k: (z[k].item() if z[k].ndim == 0 else z[k]) for k in z.files}
            except Exception as e:  # a corrupt zip raises BadZipFile, zlib.error, EOFError, …
                reason = (str(e).strip().splitlines() or [type(e).__name__])[0][:120]
                raise ValueError(one_line(f"{path}: not a readable .npz file ({reason})")) from None
        try:
            return cls.from_dict(d, source=str(path))
        except RecursionError:
            raise ValueError(f"{path}: fields nested too deeply to be a texture description") from None
