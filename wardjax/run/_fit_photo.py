"""A photograph capture fitted end to end, optionally with one photo held out and rendered.

Every pixel's K observations are one small problem, all fitted in one
batched :func:`wardjax.fit.fit_pixels` call (per-pixel ρd and, by default,
one lobe shared by the sample). With ``hold_out = k`` the fit sees the other
K − 1 photos and predicts photo ``k`` from its own geometry
(:func:`wardjax.fit.predict_pixels`, :meth:`~wardjax.capture.PhotoCapture.to_photo`);
the held-out error over the pixels photo ``k`` observes is::

    RMSE_linear  = √ mean (v_pred − v_photo)²          linear values, full scale 1
    RMSE_display = √ mean (c_pred − c_photo)²          the photos' encoding (sRGB…), in [0, 1]
    PSNR         = 20 log₁₀ (1 / RMSE_display)  dB

beside the RMSE the pixel noise alone would give, ``√ mean σ_v²``.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

from .._files import srgb8, write_bytes_atomic, write_image, write_json_atomic
from ..capture import CAPTURE_FILE, CaptureError, PhotoCapture
from ..ward import WardParams
from ._photo_verdict import Verdict, physical_verdict

__all__ = ["HeldOut", "PhotoFit", "fit_photo_capture", "write_photo_outputs"]


@dataclasses.dataclass(frozen=True, eq=False)
class HeldOut:
    """Photo ``k`` predicted by a fit of the others.

    Attributes
    ----------
    k, name
        The photo's index and file name.
    photo, prediction
        ``(H, W, C)`` linear values (NaN where photo ``k`` has no usable pixel).
    residual
        ``prediction − photo``.
    rmse_linear, rmse_display, psnr
        The errors above (PSNR in dB).
    rmse_noise
        The RMSE the pixel noise alone gives (linear), for comparison with ``rmse_linear``.
    pixels
        Pixels compared.
    sigma
        ``(H, W, C)`` the noise model's σ of each linear value of the photo (NaN where not compared).
    """

    k: int
    name: str
    photo: np.ndarray
    prediction: np.ndarray
    residual: np.ndarray
    rmse_linear: float
    rmse_display: float
    psnr: float
    rmse_noise: float
    pixels: int
    sigma: np.ndarray

    def summary(self) -> dict:
        return {
            "photo": self.k,
            "file": self.name,
            "rmse_linear": self.rmse_linear,
            "rmse_display": self.rmse_display,
            "psnr_db": self.psnr,
            "rmse_noise": self.rmse_noise,
            "pixels": self.pixels,
        }


@dataclasses.dataclass(frozen=True, eq=False)
class PhotoFit:
    """A photograph capture's fit: the :func:`~wardjax.fit.fit_pixels` result as maps, and the held-out photo.

    ``rho_d``, ``rho_d_stderr`` are ``(H, W, C)``; ``labels`` ``(H, W)``; ``normals`` ``(H, W, 3)`` or ``None``.
    """

    capture: PhotoCapture
    result: object
    rho_d: np.ndarray
    rho_d_stderr: np.ndarray
    labels: np.ndarray
    normals: np.ndarray | None
    photos_fitted: tuple[int, ...]
    held_out: HeldOut | None


def fit_photo_capture(
    cap: PhotoCapture, *, hold_out: int | None = None, lobe: str | None = None, normals: str | bool | None = None
) -> PhotoFit:
    """Fit a :class:`~wardjax.capture.PhotoCapture` (all photos, or all but ``hold_out``).

    Parameters
    ----------
    cap
        The loaded capture.
    hold_out
        Index of the photo to leave out and predict; ``None`` fits every photo.
    lobe
        ``"shared"``, ``"clusters"`` or ``"pixel"``; default ``[fit] lobe`` of ``capture.toml``.
    normals
        ``"none"``, ``"pixel"`` (a normal per problem, ``True`` too) or ``"height_field"`` (the normals tied to
        one height field over the problems' grid: :func:`~wardjax.fit_pixels`' ``height_field``); default
        ``[fit] normals`` of ``capture.toml``. Either needs two photos or more.

    Raises
    ------
    CaptureError
        ``hold_out`` out of range or leaving no photo to fit.
    """
    from ..fit import fit_pixels, predict_pixels

    h, w, k, c = cap.f_r.shape
    if hold_out is not None:
        if k < 2:
            raise CaptureError(CAPTURE_FILE, "photos", f"--hold-out needs two photos or more; {cap.name} has {k}")
        if not 0 <= hold_out < k:
            raise CaptureError(CAPTURE_FILE, "photos", f"--hold-out {hold_out}: the capture has photos 0 to {k - 1}")
    keep = [i for i in range(k) if i != hold_out]
    mode = cap.config.fit.normals if normals is None else "pixel" if normals is True else normals or "none"
    if mode != "none" and len(keep) < 2:
        raise CaptureError(
            CAPTURE_FILE,
            "fit.normals",
            f"{mode!r} needs two photos or more fitted; {cap.name} has {len(keep)}: a normal per pixel and ρd "
            "varying across pixels make the same picture in one",
        )
    b = cap.config.fit.block
    if h < b or w < b:
        raise CaptureError(CAPTURE_FILE, "fit.block", f"{b} is larger than the {w}×{h} pixels fitted")
    hh, ww = (h // b) * b, (w // b) * b
    crop = (slice(0, hh), slice(0, ww))

    def problems(a: np.ndarray, views) -> np.ndarray:
        return to_problems(a[crop][:, :, views], b)

    f, sig, m = problems(cap.f_r, keep), problems(cap.sigma, keep), problems(cap.mask, keep)
    wi, wo = problems(cap.wi, keep), problems(cap.wo, keep)
    wgt = np.where(m[..., None] & (sig > 0), 1.0 / np.where(sig > 0, sig, 1.0) ** 2, 0.0)
    res = fit_pixels(
        np.nan_to_num(f),
        wi,
        wo,
        weights=wgt,
        mask=m,
        lobe=lobe or cap.config.fit.lobe,
        model=cap.config.fit.model,
        normals=mode != "none",
        height_field=(hh // b, ww // b) if mode == "height_field" else None,
        normalization=cap.config.fit.normalization,
    )
    labels = np.repeat(np.repeat(np.asarray(res.labels).reshape(hh // b, ww // b), b, 0), b, 1)
    if b == 1:
        rho_d = np.asarray(res.rho_d).reshape(hh, ww, c)
        rho_err = np.asarray(res.stderr.rho_d).reshape(hh, ww, c)
    else:  # each pixel's own ρd under its block's lobe: π Σ w (f − specular) / Σ w, σ = π / √Σ w
        spec = from_problems(np.asarray(predict_pixels(_without_diffuse(res), wi, wo)), hh, ww, b)
        wk = from_problems(wgt, hh, ww, b)
        sw = wk.sum(axis=2)
        fk = np.nan_to_num(cap.f_r[crop][:, :, keep])
        with np.errstate(invalid="ignore", divide="ignore"):
            rho_d = np.where(sw > 0, np.pi * np.sum(wk * (fk - spec), axis=2) / sw, np.nan)
            rho_err = np.where(sw > 0, np.pi / np.sqrt(sw), np.nan)
    held = None
    if hold_out is not None:
        pred = predict_pixels(res, problems(cap.wi, [hold_out]), problems(cap.wo, [hold_out]))
        held = _held_out(cap, hold_out, from_problems(np.asarray(pred), hh, ww, b)[:, :, 0], crop)
    n = getattr(res, "normals", None)
    return PhotoFit(
        cap,
        res,
        rho_d,
        rho_err,
        labels,
        None if n is None else np.repeat(np.repeat(np.asarray(n).reshape(hh // b, ww // b, 3), b, 0), b, 1),
        tuple(keep),
        held,
    )


def to_problems(a: np.ndarray, b: int) -> np.ndarray:
    """``(H, W, K, …)`` → ``(H/b · W/b, b² K, …)``: each ``b × b`` block of pixels one problem of ``b² K`` views."""
    h, w, k = a.shape[:3]
    rest = a.shape[3:]
    a = a.reshape(h // b, b, w // b, b, k, *rest)
    a = np.moveaxis(a, 2, 1)  # (H/b, W/b, b, b, K, …)
    return a.reshape((h // b) * (w // b), b * b * k, *rest)


def from_problems(a: np.ndarray, h: int, w: int, b: int) -> np.ndarray:
    """The inverse of :func:`to_problems`: ``(H/b · W/b, b² K, …)`` → ``(H, W, K, …)``."""
    k = a.shape[1] // (b * b)
    rest = a.shape[2:]
    a = a.reshape(h // b, w // b, b, b, k, *rest)
    return np.moveaxis(a, 1, 2).reshape(h, w, k, *rest)


def _without_diffuse(res):
    """The fit with ρd = 0: its prediction is the lobes' (specular) part alone."""
    return dataclasses.replace(res, rho_d=np.zeros_like(np.asarray(res.rho_d)))


def _held_out(cap: PhotoCapture, k: int, f_pred: np.ndarray, crop) -> HeldOut:
    photo = cap.linear[crop][:, :, k]
    pred = f_pred * cap.scale[crop][:, :, k] + cap.dark[crop][:, :, k]
    ok = cap.mask[crop][:, :, k] & np.all(np.isfinite(pred), axis=-1)
    if not ok.any():
        raise CaptureError(cap.photos[k], None, "has no usable pixel to compare the prediction with")
    diff = (pred - photo)[ok]
    disp = cap.display(np.clip(pred, 0, 1))[ok] - cap.display(photo)[ok]
    rmse_d = float(np.sqrt(np.mean(disp**2)))
    sig = cap.sigma[crop][:, :, k] * cap.scale[crop][:, :, k]
    sig_v = sig[ok]
    nan = np.where(ok[..., None], 1.0, np.nan)
    return HeldOut(
        k,
        cap.photos[k],
        photo * nan,
        pred * nan,
        (pred - photo) * nan,
        float(np.sqrt(np.mean(diff**2))),
        rmse_d,
        float(20 * np.log10(1.0 / max(rmse_d, 1e-12))),
        float(np.sqrt(np.mean(sig_v**2))),
        int(ok.sum()),
        sig * nan,
    )


# --------------------------------------------------------------------------- outputs


def _lobes(res, field: str) -> list[float]:
    return np.atleast_1d(np.asarray(getattr(res, field), np.float64)).ravel().tolist()


def write_photo_outputs(fit: PhotoFit, out_dir, *, created: str) -> dict:
    """Write the ρd map and its σ (``.tif``), ``maps.npz``, ``heldout.png``, ``report.md``, then ``params.json``."""
    from ..export._params import params_document

    cap, res = fit.capture, fit.result
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    rho_s, ax, ay = _lobes(res, "rho_s"), _lobes(res, "alpha_x"), _lobes(res, "alpha_y")
    st = res.stderr  # pyright: ignore[reportAttributeAccessIssue]
    srho_s, sax, say = (
        np.atleast_1d(np.asarray(getattr(st, n), float)).ravel().tolist() for n in ("rho_s", "alpha_x", "alpha_y")
    )
    rho_mean = np.nanmean(fit.rho_d.reshape(-1, fit.rho_d.shape[-1]), axis=0)
    n_ok = np.sum(np.isfinite(fit.rho_d[..., 0]))
    rho_err = np.sqrt(np.nansum(fit.rho_d_stderr.reshape(-1, 3) ** 2, axis=0)) / max(n_ok, 1)
    # the estimate as measured: a fit may leave the physical range (the verdict below says so)
    params = WardParams.from_estimate(rho_d=rho_mean, rho_s=rho_s[0], alpha_x=ax[0], alpha_y=ay[0])
    stderr = WardParams.from_estimate(rho_d=rho_err, rho_s=srho_s[0], alpha_x=sax[0], alpha_y=say[0])
    chi2, dof = float(getattr(res, "chi2", np.nan)), int(getattr(res, "dof", 0))
    lobes = {"rho_s": rho_s, "alpha_x": ax, "alpha_y": ay, "rho_s_err": srho_s, "alpha_x_err": sax, "alpha_y_err": say}
    verdict = physical_verdict(
        rho_mean,
        rho_err,
        lobes,
        chi2_per_dof=chi2 / dof if dof > 0 else None,
        rho_d_map=fit.rho_d,
        rho_d_map_err=fit.rho_d_stderr,
    )
    files = {}
    if verdict.physical:  # the texture a renderer loads: not written with values no material has
        write_image(out / "rho_d.tif", fit.rho_d.astype(np.float32))
        write_image(out / "rho_d.png", srgb8(fit.rho_d))
        write_image(out / "rho_d_sigma.tif", fit.rho_d_stderr.astype(np.float32))
        files = {"rho_d": "rho_d.tif", "rho_d_png": "rho_d.png", "rho_d_sigma": "rho_d_sigma.tif"}
    maps = {"rho_d": fit.rho_d, "rho_d_stderr": fit.rho_d_stderr, "labels": fit.labels, "mask": cap.mask}
    if fit.normals is not None:
        maps["normals"] = fit.normals
    import io

    buf = io.BytesIO()
    np.savez_compressed(buf, **maps)  # pyright: ignore[reportArgumentType]
    write_bytes_atomic(out / "maps.npz", buf.getvalue())
    files["maps"] = "maps.npz"
    if fit.held_out is not None:
        from ._heldout_figure import heldout_png

        write_bytes_atomic(out / "heldout.png", heldout_png(fit.held_out))
        files["heldout"] = "heldout.png"
    fit_doc = {
        "status": "converged" if verdict.physical else "not_physical",
        "verdict": None if verdict.physical else verdict.line(cap.name, cap.photos),
        "held_to_range": list(verdict.notes),
        "reduced_chi2": chi2 / dof if dof > 0 else None,
        "weighted": True,  # 1/σ² from the noise model: a χ²/dof (wardjax.export.fit_quality)
        "chi2": chi2,
        "dof": dof,
        "lobe": getattr(res, "lobe", cap.config.fit.lobe),
        "lobes": lobes,
        "photos": list(cap.photos),
        "photos_fitted": list(fit.photos_fitted),
        "held_out": None if fit.held_out is None else fit.held_out.summary(),
        "light_power": cap.light_power.tolist(),
        "exposures": cap.exposures.tolist(),
        "pixel_mm": cap.pixel_mm,
        "notes": list(cap.notes),
        "diagnostics": {"pixels": {"valid": int(np.sum(cap.mask.any(axis=-1))), "total": int(cap.mask[..., 0].size)}},
    }
    files["report"] = "report.md"
    write_bytes_atomic(out / "report.md", report_text(fit, params, stderr, fit_doc, verdict).encode())
    nan = WardParams.from_estimate(rho_d=np.full(3, np.nan), rho_s=np.nan, alpha_x=np.nan, alpha_y=np.nan)
    radiance = {  # the material: the estimate held to the physical ranges, or nothing (JSON null) when it is none
        "normalization": cap.config.fit.normalization,
        "params": verdict.material if verdict.material is not None else nan,
        "stderr": stderr if verdict.physical else nan,
        "status": "not exported: photograph fits are not refitted in Radiance's normalisation yet"
        if verdict.physical
        else "not exported: not a physical material (fit.verdict)",
        "tangent": [1.0, 0.0],
    }
    doc = params_document(
        name=cap.name,
        method=cap.method,
        model=cap.config.fit.model,
        normalization=cap.config.fit.normalization,
        params=params,
        stderr=stderr,
        fit=fit_doc,
        radiance=radiance,
        files=files,
        inputs=cap.checksums,
        created=created,
    )
    write_json_atomic(out / "params.json", doc)
    from .._files import jsonable

    return jsonable(doc)


def _pm(value: float, err: float) -> str:
    """``value ± err``; an error that rounds to zero at 4 decimals in scientific notation."""
    return f"{value:.4f} ± {err:.4f}" if abs(err) >= 5e-5 or not np.isfinite(err) else f"{value:.4f} ± {err:.1e}"


def report_text(fit: PhotoFit, params: WardParams, stderr: WardParams, doc: dict, verdict: Verdict) -> str:
    """``report.md``: the capture, what the loader assumed, the lobes with σ, the held-out photo's errors."""
    cap = fit.capture
    lines = [
        f"# {cap.name} ({cap.method}, {len(cap.photos)} photo{'s' if len(cap.photos) > 1 else ''})",
        "",
        f"Photos: {', '.join(cap.photos)}; fitted: {', '.join(cap.photos[i] for i in fit.photos_fitted)}.",
        f"Pixel on the sample: {cap.pixel_mm:.3g} mm; "
        f"light power P = {', '.join(f'{p:.4g}' for p in cap.light_power)}.",
        "",
    ]
    lines += [f"- {n}" for n in cap.notes]
    rd = ", ".join(f"{v:.4f} ± {e:.1e}" for v, e in zip(np.asarray(params.rho_d), np.asarray(stderr.rho_d)))
    lines += [
        "",
        f"Mean ρd (linear sRGB primaries, white E): {rd}",
        "",
        "| lobe | ρs | αx | αy |",
        "| --- | --- | --- | --- |",
    ]
    lob = doc["lobes"]
    for i, (s, a, b) in enumerate(zip(lob["rho_s"], lob["alpha_x"], lob["alpha_y"])):
        es, ea, eb = lob["rho_s_err"][i], lob["alpha_x_err"][i], lob["alpha_y_err"][i]
        lines.append(f"| {i} | {_pm(s, es)} | {_pm(a, ea)} | {_pm(b, eb)} |")
    if doc["reduced_chi2"] is not None:
        lines += ["", f"χ²/dof = {doc['reduced_chi2']:.3g} ({doc['dof']} degrees of freedom)."]
        if doc["reduced_chi2"] > 2:
            lines.append(
                "χ²/dof well above 1: the model leaves structure the pixel noise does not explain (texture within a "
                "block, the lamp's angular falloff, the camera's processing); the σ above hold only if the model did."
            )
    if not verdict.physical:
        lines += ["", f"**{doc['verdict']}.**"]
    lines += [f"- {n}" for n in verdict.notes]
    ho = fit.held_out
    if ho is not None:
        lines += [
            "",
            f"Held-out photo {ho.k} ({ho.name}), predicted from the other {len(fit.photos_fitted)}: "
            f"RMSE {ho.rmse_linear:.4g} linear ({ho.rmse_linear / ho.rmse_noise:.2f}× the noise, {ho.rmse_noise:.3g}), "
            f"{ho.rmse_display:.4g} display, PSNR {ho.psnr:.2f} dB over {ho.pixels} pixels. "
            "heldout.png: photo | prediction (linear values, one scale) | residual (in noise σ).",
        ]
    return "\n".join(lines) + "\n"


def fit_photo_outputs(cap: PhotoCapture, out_dir: Path, *, created: str, hold_out: int | None = None) -> dict:
    """The batch's fitter for ``flash`` and ``multiview`` captures: fit, then write the outputs."""
    return write_photo_outputs(fit_photo_capture(cap, hold_out=hold_out), out_dir, created=created)
