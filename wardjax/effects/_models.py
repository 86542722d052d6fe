"""The models :func:`~wardjax.effects.discover` can extend, and the data they take.

A model exposes what ``discover`` needs (see "Missing effects" in DESIGN.md):
its own parameters (:meth:`base_params`), whitened residuals for given
parameter values and a set of active effects (:meth:`residuals`, a pure JAX
function), predictions (:meth:`predict`), and named covariates per
observation (:meth:`covariates`) against which residual structure is tested.
Effects extend a model through the hooks it calls (:class:`Effect` methods).

Scanline model
    BRDF samples ``f_r`` on ``S`` scanlines × ``N`` samples × ``C`` channels
    (reconstructed ``v/v_std`` values of the image-based rig, or measured
    BRDFs such as CUReT's). Prediction, with every effect at its absent value
    the isotropic Ward model of the papers (image-based paper, eq. for
    ``f_r,Ward``; :func:`wardjax.ward_brdf`)::

        f = ρd[s, c]/π + ρs · q_c · F(θd) · S(h; αx, αy, φ) + Σ extra terms
        f_meas = M(f)            # measurement effects, in order

    ``ρd`` per scanline and channel is *profiled*: the observations are mapped
    back through the (monotone) measurement chain, ``y' = M⁻¹(y)`` with
    ``σ' = σ |dM⁻¹/dy|`` (delta method, exact to first order in ``σ/y``), where
    ρd is linear and solved in closed form (a weighted mean) for every trial
    of the other parameters. The residual is exact, ``(y − M(f))/σ``;
    observations a saturation effect declares censored contribute
    ``−2 log Φ((M(f) − y)/σ)`` instead (the censored likelihood) and are left
    out of the ρd mean.

Threshold model
    Table 1 of the smartphone paper: lobe SD against threshold PPB, one line
    for all lightnesses, ``SD = a + b · PPB`` (paper section 6, Fig. 8a), with
    effects changing the slope (contrast gloss) or adding terms.
"""

from __future__ import annotations

import dataclasses

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.scipy.special import log_ndtr

from ..ward import NORMALIZATIONS, ward_geometry
from ._effect import Param
from ._gls import _TINY, _gls_design, _gls_rho, _gls_solve, _whiten

__all__ = ["ScanlineData", "ScanlineModel", "ThresholdData", "ThresholdModel", "scanline_data", "threshold_data"]

LENGTH_SCALE_MM = 100.0


# ============================================================================ data


class ScanlineData(eqx.Module):
    """Observations for the scanline model (build with :func:`scanline_data`).

    Attributes
    ----------
    y, sigma
        ``(S, N, C)`` observed BRDF values (sr⁻¹) and their noise SD.
    mask
        ``(S, N, C)`` bool, the observation is used.
    wi, wo
        ``(S, N, 3)`` unit directions to light and camera, material frame.
    cov
        Extra covariates, ``(S, N)`` each: ``x``, ``y`` (mm; ``x`` across the
        stripline), ``inv_irradiance`` (lamp ``r²/cos θi``, mean 1).
    kind
        ``"ratio"`` (reconstructed ``v/v_std``: effects symmetric about the
        stripline cancel) or ``"brdf"`` (calibrated BRDF values).
    f_std
        ``ρ_std/π`` of the reflectance standard (the ratio's reference level).
    censored
        ``(S, N, C)`` bool or ``None``: the value is known to be clipped — a
        *lower bound* on the true value (a saturated pixel whose clip level
        the sensor reports). The saturation effect fits these with the
        censored likelihood; without the flags it finds clipped values as a
        plateau of tied maxima.
    whiten
        ``(S, C, N, N)``, ``(S, C N, C N)`` (the channels of a scanline
        together) or ``None``: lower-triangular ``L⁻¹`` that whitens the
        residuals along each scanline when the probe's ρd texture is carried
        in the model as a Gaussian process (:mod:`wardjax.effects._texture`);
        ``None``: white noise.
    levels
        ``(P, a)`` or ``None``: the texture between scanlines carried in their
        diffuse levels (:mod:`~wardjax.effects._levels`); the residuals gain
        ``P ℓ``, ``ℓ = ρd a`` the scanlines' relative levels (``P`` ``(S, S)``,
        ``n`` non-zero rows of rank ``n − 1``: that many more observations;
        ``a`` ``(C,)``). All zeros: the same compiled program, no term.
    standard
        ``(c, R, columns)`` or ``None``: the smoothed reflectance standard's
        relative noise ``c`` ``(S, N, C)`` at each value's mirror point, its correlation ``R`` at bin
        lags and each scanline's bin column ``(S,)``
        (:mod:`~wardjax.effects._standard_noise`); read only by the fitted
        parameters' covariance (:mod:`~wardjax.effects._standard_sigma`).
    pixels
        ``None`` or the pixel levels behind each ratio value (a capture's):
        ``lit_std``, ``dark_std``, ``dark_probe``, ``ref`` ``(S, N, C)``, the
        lit frame blurred wide at the probe and the standard (``glare_probe``,
        ``glare_std``, read by the veiling glare), and for an sRGB or power-2.2
        file the other encoding's reading of them (``lit_probe``, ``alt_*``),
        read by the encoding effect (:mod:`~wardjax.effects._pixel_levels`).
    dark
        ``(D, R)`` or ``None``: the dark frame's level at each value's probe
        pixels ``D`` and the room's light under it ``R`` (the dark frame
        smoothed over 10 px), ``(S, N, C)`` each, binned as the values (a
        capture with a dark frame); read only by the texture's check
        (:mod:`~wardjax.effects._dark_texture`).
    """

    y: np.ndarray
    sigma: np.ndarray
    mask: np.ndarray
    wi: np.ndarray
    wo: np.ndarray
    cov: dict
    censored: np.ndarray | None = None
    whiten: np.ndarray | None = None
    levels: tuple | None = None
    standard: tuple | None = None
    pixels: dict | None = None
    dark: tuple | None = None
    kind: str = eqx.field(static=True, default="ratio")
    f_std: float = eqx.field(static=True, default=0.99 / np.pi)
    available: tuple = eqx.field(static=True, default=())

    @property
    def shape(self) -> tuple[int, int, int]:
        return tuple(self.y.shape)

    @property
    def n_obs(self) -> int:
        rows = 0 if self.levels is None else int(np.sum(np.any(np.asarray(self.levels[0]) != 0, axis=1)))
        return int(np.sum(np.asarray(self.mask))) + max(rows - 1, 0)


def scanline_data(
    f_r,
    wi,
    wo,
    sigma,
    *,
    mask=None,
    points=None,
    lamp=None,
    kind: str = "ratio",
    rho_standard: float = 0.99,
    censored=None,
    camera=None,
) -> ScanlineData:
    """Build :class:`ScanlineData` from arrays, checking shapes at the boundary.

    Parameters
    ----------
    f_r
        ``(S, N, C)`` BRDF values (``(S, N)`` is taken as ``C = 1``); NaN marks missing.
    wi, wo
        ``(S, N, 3)`` unit directions (material frame, pointing away from the surface).
    sigma
        Noise SD, broadcastable to ``f_r``.
    mask
        Optional ``(S, N)`` or ``(S, N, C)`` bool of usable values.
    points
        Optional ``(S, N, 3)`` sample positions (mm; x across the stripline):
        gives the covariates ``x``, ``y``.
    lamp
        Optional lamp position(s) (mm), ``(3,)`` or ``(S, 3)``: gives
        ``inv_irradiance = r²/cos θi`` normalised to mean 1.
    kind
        ``"ratio"`` or ``"brdf"`` (see :class:`ScanlineData`).
    rho_standard
        Reflectance of the standard (the paper's BaSO₄, ≈ 0.99).
    censored
        Optional ``(S, N)`` or ``(S, N, C)`` bool: ``f_r`` there is a lower
        bound (clipped at a known level), to be fitted with the censored
        likelihood rather than dropped (see :class:`ScanlineData`).
    camera
        Optional :class:`~wardjax.geometry.Camera` that took the image: with
        ``points``, the illumination field is then read in image coordinates
        (:func:`_field_coordinates`).
    """
    f = np.asarray(f_r, np.float64)
    if f.ndim == 2:
        f = f[..., None]
    if f.ndim != 3:
        raise ValueError(f"f_r must have shape (S, N, C) or (S, N), got {np.shape(f_r)}")
    s, n, c = f.shape
    wi = np.asarray(wi, np.float64)
    wo = np.asarray(wo, np.float64)
    for name, w in (("wi", wi), ("wo", wo)):
        if w.shape != (s, n, 3):
            raise ValueError(f"{name} must have shape {(s, n, 3)} to match f_r, got {w.shape}")
    sig = np.broadcast_to(
        np.asarray(sigma, np.float64) if np.ndim(sigma) != 2 else np.asarray(sigma)[..., None], f.shape
    ).copy()
    if kind not in ("ratio", "brdf"):
        raise ValueError(f"kind must be 'ratio' or 'brdf', got {kind!r}")
    m = np.isfinite(f) & np.isfinite(sig) & (sig > 0)
    m &= (wi[..., 2:3] > 1e-6) & (wo[..., 2:3] > 1e-6)
    if mask is not None:
        mk = np.asarray(mask, bool)
        m &= mk[..., None] if mk.ndim == 2 else mk
    if not m.any():
        raise ValueError("no usable observation: every value is masked, non-finite, or has sigma <= 0")
    cov = {}
    if points is not None:
        pts = np.asarray(points, np.float64)
        if pts.shape != (s, n, 3):
            raise ValueError(f"points must have shape {(s, n, 3)}, got {pts.shape}")
        cov["x"] = pts[..., 0]
        cov["y"] = pts[..., 1]
        cov["illum_s"], cov["illum_st"] = _field_coordinates(pts, camera)
        if lamp is not None:
            w = inv_irradiance(pts, lamp, wi)
            cov["inv_irradiance"] = w / np.mean(w[m.any(-1)])
    cens = None
    if censored is not None:
        ck = np.asarray(censored, bool)
        ck = ck[..., None] if ck.ndim == 2 else ck
        if ck.shape[:2] != (s, n) or ck.shape[-1] not in (1, c):
            raise ValueError(f"censored must have shape {(s, n)} or {(s, n, c)}, got {np.shape(censored)}")
        cens = np.broadcast_to(ck, f.shape) & m
    f = np.where(m, f, 0.0)
    sig = np.where(m, sig, 1.0)
    avail = tuple(sorted(cov)) + (("rgb",) if c == 3 else ())
    # NumPy float64 leaves: they become float64 JAX arrays inside the fits' scoped x64
    return ScanlineData(
        y=f,
        sigma=sig,
        mask=m,
        wi=wi,
        wo=wo,
        cov=cov,
        censored=cens,
        kind=kind,
        f_std=float(rho_standard) / np.pi,
        available=avail,
    )


def inv_irradiance(points: np.ndarray, lamp, wi: np.ndarray) -> np.ndarray:
    """The lamp's inverse irradiance ``r²/cos θi`` ``(S, N)`` at ``points`` ``(S, N, 3)`` (mm) lit from ``lamp``
    ``(3,)`` or ``(S, 3)`` along ``wi`` ``(S, N, 3)`` (material frame)."""
    lp = np.asarray(lamp, np.float64)
    lp = lp[:, None, :] if lp.ndim == 2 else lp[None, None, :]
    return np.sum((lp - points) ** 2, axis=-1) / np.maximum(wi[..., 2], 1e-6)


def _field_coordinates(points: np.ndarray, camera=None) -> tuple[np.ndarray, np.ndarray]:
    """``Δs`` and ``Δ(st)`` between each point and its mirror point (the illumination field's covariates).

    ``(s, t)`` are image coordinates from the principal point in image widths
    when ``camera`` is given, else ``(x, y)/100 mm``; ``Δ· = ·(p) − ·(p')`` with
    ``p' = (−x, y, z)`` (see :class:`~wardjax.effects._library.IlluminationGradient`).
    """
    from ..geometry import mirror_point, project

    def st(q):
        if camera is None:
            return q[..., 0] / 100.0, q[..., 1] / 100.0
        uv, _ = project(camera, q)
        cu, cv = camera.principal
        return (uv[..., 0] - cu) / camera.width, (uv[..., 1] - cv) / camera.width

    fin = np.all(np.isfinite(points), axis=-1, keepdims=True)
    q = np.where(fin, points, 0.0)
    (s1, t1), (s2, t2) = st(q), st(mirror_point(q))
    ds, dst = np.nan_to_num(s1 - s2), np.nan_to_num(s1 * t1 - s2 * t2)
    return ds, dst


class ThresholdData(eqx.Module):
    """Threshold observations: lobe SD (degrees) against threshold PPB, per surface.

    Attributes
    ----------
    ppb, sd, sigma
        ``(n,)`` threshold pixels per bar, measured lobe SD and its noise SD.
    rho_d
        ``(n,)`` diffuse reflectance of each surface (the contrast-gloss covariate).
    group
        ``(n,)`` int lightness group (for the plots).
    """

    ppb: np.ndarray
    sd: np.ndarray
    sigma: np.ndarray
    rho_d: np.ndarray
    group: np.ndarray
    labels: tuple = eqx.field(static=True, default=())
    kind: str = eqx.field(static=True, default="threshold")
    available: tuple = eqx.field(static=True, default=("rho_d",))

    @property
    def n_obs(self) -> int:
        return int(self.sd.shape[0])


def threshold_data(ppb, sd, sigma, rho_d, group=None, labels=()) -> ThresholdData:
    """Build :class:`ThresholdData`, checking shapes and values at the boundary."""
    arrs = [np.asarray(a, np.float64).ravel() for a in (ppb, sd, sigma, rho_d)]
    n = arrs[0].size
    for name, a in zip(("ppb", "sd", "sigma", "rho_d"), arrs):
        if a.size != n:
            raise ValueError(f"{name} has {a.size} values, ppb has {n}")
        if not np.all(np.isfinite(a)):
            raise ValueError(f"{name} holds non-finite values")
    if np.any(arrs[2] <= 0):
        raise ValueError("sigma must be > 0")
    g = np.zeros(n, np.int32) if group is None else np.asarray(group, np.int32).ravel()
    return ThresholdData(*arrs, group=g, labels=tuple(labels))


# ============================================================================ scanline model


def _lobe(ctx, ax, ay, phi):
    """Ward specular lobe per unit ρs with the tangent frame turned by φ about the normal."""
    c, s = jnp.cos(phi), jnp.sin(phi)
    hx = c * ctx["hx"] + s * ctx["hy"]
    hy = -s * ctx["hx"] + c * ctx["hy"]
    e = (hx * hx / (ax * ax) + hy * hy / (ay * ay)) / ctx["hz2"]
    return ctx["g"] * jnp.exp(-e) / (ax * ay)


def _gated(on, hook, x):
    """``hook(x)`` where the effect is switched on, ``x`` unchanged where it is off.

    ``on`` is the effect's traced flag in a fit (``discover`` switches effects
    by data, so one compiled program serves every candidate): a ``lax.cond``
    then runs only the branch taken, so an inactive effect costs nothing in
    the residuals or their Jacobian — unbatched; under ``vmap`` with a batched
    flag JAX evaluates both branches, as before. At their absent values the
    hooks are the identity (to rounding), so the result is the same either
    way. ``on`` absent (``None``) or a Python bool: the hook is applied as is.
    """
    if on is None or isinstance(on, bool):
        return hook(x)
    if on is _IDENTITY:
        return x
    return jax.lax.cond(
        on,
        lambda x: jax.tree_util.tree_map(lambda a, b: jnp.broadcast_to(a, jnp.shape(b)).astype(b.dtype), hook(x), x),
        lambda x: x,
        x,
    )


_IDENTITY = object()  # a hook the effect does not override: the base class's identity, nothing to evaluate


def _switch(active, e, hook: str):
    """The flag :func:`_gated` takes for effect ``e``'s ``hook``: its entry in ``active``, or :data:`_IDENTITY`.

    A hook the effect inherits from the scanline base class (``_ScanlineEffect``
    in :mod:`wardjax.effects._library`, where every hook is the identity) is
    skipped outright: a ``lax.cond`` around an identity still copies the
    array and breaks XLA's fusion.
    """
    for cls in type(e).__mro__:
        if hook in vars(cls):
            if cls.__name__ == "_ScanlineEffect":
                return _IDENTITY
            break
    return None if active is None else active.get(e.name)


def _whitened_design(data) -> jnp.ndarray:
    """``L⁻¹`` of ``1/σ`` on each channel alone (zero off the mask), ``(S, N, C, C_cols)``: ρd's design, whitened."""
    return _gls_design(data.whiten, jnp.where(data.mask, 1.0 / data.sigma, 0.0))


def _measured_as_is(active, effects):
    """Whether no active effect maps the model's values to the measured ones (``measure``/``unmeasure``) or
    censors them: ``True``/``False``, a traced flag (a fit's ``active``), or ``None`` (every hook applies)."""
    flags = []
    for e in effects:
        hooks = (_switch(active, e, h) for h in ("measure", "unmeasure"))
        if getattr(e, "censors", False) or any(h is not _IDENTITY for h in hooks):
            flag = None if active is None else active.get(e.name)
            if flag is None:
                return None
            flags.append(flag)
    if not flags:
        return True
    if all(isinstance(f, bool) for f in flags):
        return not any(flags)
    return ~jnp.any(jnp.stack([jnp.asarray(f) for f in flags]))


@dataclasses.dataclass(frozen=True)
class ScanlineModel:
    """Isotropic Ward on scanlines with ρd per scanline and channel (see module docstring).

    Parameters
    ----------
    normalization
        Ward normalisation (:data:`wardjax.NORMALIZATIONS`).
    """

    normalization: str = "ward1992"
    kind = "scanline"
    data_kinds = ("ratio", "brdf")  # ScanlineData.kind values it fits
    library_kind = "scanline"  # whose library() its candidates come from
    title = "isotropic Ward, ρd per scanline and channel, shared ρs and α"

    @staticmethod
    def supports(e) -> bool:
        """Whether the model implements ``e``'s forward change: every scanline effect."""
        return e.model == "scanline"

    def __post_init__(self):
        if self.normalization not in NORMALIZATIONS:
            raise ValueError(f"normalization={self.normalization!r} is not one of {NORMALIZATIONS}")

    def base_params(self, data: ScanlineData) -> tuple[Param, ...]:
        y = np.asarray(data.y)
        m = np.asarray(data.mask)
        peak = float(np.max(np.where(m, y, -np.inf)) - np.median(y[m]))
        return (
            Param(
                "rho_s",
                max(peak * 4 * np.pi * 0.1**2, 1e-3),
                kind="log",
                scale=0.05,
                unit="",
                doc="specular reflectance",
                starts=(),
            ),
            Param("alpha", 0.1, kind="log", scale=0.1, starts=(0.03, 0.3), doc="lobe width (RMS slope)"),
        )

    def n_profiled(self, data: ScanlineData) -> int:
        return int(np.sum(np.asarray(data.mask).any(axis=1)))

    # ---------------------------------------------------------------- forward
    def context(self, data: ScanlineData) -> dict:
        """Geometry that does not change during a fit, computed once."""
        wi, wo = data.wi, data.wo
        geom = ward_geometry(wi, wo, self.normalization)
        h = wi + wo
        hz = jnp.where(geom.valid, h[..., 2], 1.0)
        hn = jnp.sqrt(jnp.sum(h * h, axis=-1))
        ctx = {
            "hx": h[..., 0],
            "hy": h[..., 1],
            "hz2": hz * hz,
            "g": geom.g,
            "valid": geom.valid,
            "cos_d": jnp.clip(jnp.sum(h * wi, axis=-1) / hn, 0.0, 1.0),
            "psi": jnp.arccos(jnp.clip(jnp.sum(wi * wo, axis=-1), -1.0 + 1e-12, 1.0 - 1e-12)),
            "f_std": data.f_std,
        }
        ctx.update(data.cov)
        if data.pixels is not None:
            ctx.update(data.pixels)
        if data.whiten is not None:  # once per solve, not once per residual evaluation
            ctx["whitened_design"] = _whitened_design(data)
        return ctx

    def _parts(self, vals, effects, data, ctx, active=None):
        """The Ward terms without ρd: ``(S, N, C)`` specular plus extra terms."""
        base = vals["model"]
        ax = ay = base["alpha"]
        phi = 0.0
        for e in effects:
            ax, ay, phi = e.lobe(vals[e.name], ax, ay, phi)
        spec = _lobe(ctx, ax, ay, phi)
        for e in effects:
            spec = _gated(_switch(active, e, "spec_factor"), lambda s, e=e: s * e.spec_factor(vals[e.name], ctx), spec)
        c = data.y.shape[-1]
        rs = base["rho_s"] * jnp.ones((c,))
        for e in effects:
            rs = rs * e.rho_s_factor(vals[e.name], c)
        term = rs[None, None, :] * spec[..., None]
        for e in effects:
            term = _gated(
                _switch(active, e, "extra"), lambda t, e=e: t + e.extra(vals[e.name], ctx, base, ax, ay, phi), term
            )
        return jnp.where(ctx["valid"][..., None], term, 0.0)

    def _unmeasure(self, vals, effects, data, ctx, active=None):
        """Observations mapped back through the measurement effects: ``y'`` and ``σ' = σ |dy'/dy|``.

        The measurement chain ``f_meas = M(f)`` is monotone; comparing ``M⁻¹(y)``
        with ``f`` under the propagated noise (delta method, exact to first order
        in ``σ/y``) keeps ρd linear, so it is profiled in closed form.
        """

        def step(e, yd):
            y, dd = e.unmeasure(vals[e.name], yd[0], ctx)
            return y, yd[1] * dd

        yd = (data.y, jnp.ones_like(data.y))
        for e in reversed(effects):
            yd = _gated(_switch(active, e, "unmeasure"), lambda yd, e=e: step(e, yd), yd)
        return yd[0], data.sigma * jnp.abs(yd[1])

    def _profile(self, vals, active, effects, data, ctx):
        """Profiled ρd per scanline and channel, whitened residuals, prediction."""
        term = self._parts(vals, effects, data, ctx, active)
        cens = jnp.zeros(data.y.shape, bool)
        censoring = any(getattr(e, "censors", False) for e in effects)
        if censoring:
            for e in effects:
                cens = cens | e.censored(active[e.name], data)

        def general(_):
            yp, sp = self._unmeasure(vals, effects, data, ctx, active)
            # ρd from the uncensored values (a censored value only bounds it)
            use = data.mask & ~cens
            if data.whiten is None:
                w = jnp.where(use, 1.0 / (sp * sp), 0.0)
                sw = jnp.sum(w, axis=1, keepdims=True)
                rho = jnp.pi * jnp.sum(w * (yp - term), axis=1, keepdims=True) / jnp.maximum(sw, _TINY)
            else:  # generalised least squares under the texture's covariance
                rho = _gls_rho(data.whiten, jnp.where(use, 1.0 / sp, 0.0), jnp.where(use, (yp - term) / sp, 0.0))
            f = rho / jnp.pi + term
            # the deviance is exact, in the measured space: ρd above is the closed-form profile
            # of the linearised problem (close to, never better than, the exact optimum), so a
            # measurement effect cannot lower χ² by stretching the propagated noise
            for e in effects:
                f = _gated(_switch(active, e, "measure"), lambda f, e=e: e.measure(vals[e.name], f, ctx), f)
            z = jnp.where(data.mask, (data.y - f) / data.sigma, 0.0)
            if data.whiten is not None:  # decoupled (identity) rows where a value is flagged clipped or masked
                z = _whiten(data.whiten, z)
            return rho, f, z

        plain = None if data.whiten is None else _measured_as_is(active, effects)
        if plain is None or plain is False:
            rho, f, z = general(None)
        else:
            design = ctx["whitened_design"]  # set by context() whenever the data are whitened

            def direct(_):
                # nothing between the model and the measured values: the residual is linear in ρd, so its
                # whitened form is L⁻¹ of (y − Ward terms)/σ less the whitened design times ρd/π — one
                # whitening per evaluation (and per Jacobian column) instead of five
                b = _whiten(data.whiten, jnp.where(data.mask, (data.y - term) / data.sigma, 0.0))
                rho = _gls_solve(design, b)
                z = b - jnp.einsum("snck,sk->snc", design, rho[:, 0, :] / jnp.pi)
                return rho, rho / jnp.pi + term, z

            rho, f, z = direct(None) if plain is True else jax.lax.cond(plain, direct, general, None)
        if censoring:
            # a censored value says only "true value ≥ y": P = Φ((f − y)/σ)
            t = jnp.where(cens, -z, 0.0)
            rc = jnp.sqrt(jnp.maximum(-2.0 * log_ndtr(t), 0.0) + 1e-12)
            z = jnp.where(cens, rc, z)
        r = jnp.where(data.mask, z, 0.0)
        return r, f, rho, cens

    def residuals(self, vals, active, effects, data, ctx=None):
        """Whitened residuals, flat: the values' ``(S N C)``, then the scanline levels' (``data.levels``)."""
        return self.evaluate(vals, active, effects, data, ctx)[0]

    def evaluate(self, vals, active, effects, data, ctx=None):
        """:meth:`residuals` and :meth:`predict`'s prediction ``(S, N, C)`` and profiled ρd ``(S, 1, C)`` from one
        evaluation of the model (a traced program holds one copy of it, not two)."""
        ctx = self.context(data) if ctx is None else ctx
        r, f, rho, _ = self._profile(vals, active, effects, data, ctx)
        if data.levels is None:
            return r.reshape(-1), f, rho
        P, a = data.levels
        lv = P @ (rho[:, 0, :] @ a) / self._level_slope(vals, active, effects, data, ctx)
        return jnp.concatenate([r.reshape(-1), lv]), f, rho

    def _level_slope(self, vals, active, effects, data, ctx):
        """The measurement chain's mean slope ``D = ⟨∂M⁻¹/∂y⟩`` at the baseline's mean diffuse level (1 without one).

        The levels' Gaussian process (:mod:`~wardjax.effects._levels`) is measured on the baseline's ρd, which are
        in the measured space. A measurement effect maps the values back before ρd is profiled, and so stretches
        every scanline's deviation from the mean level by its slope ``D``: a response ``f_std (f/f_std)^{1+ε}``
        shrinks them by ``1/(1+ε)``, which the fixed covariance read as a better fit by ``(1 − D²) χ²_levels``
        whatever the data (an untouched wood desk named γ on the levels alone, its values' Δχ² negative). The
        levels' residuals are divided by ``D``, the first-order Jacobian back to the measured space; a
        multiplicative field keeps its trend across the scanlines (``D`` is its mean), an offset its level.
        """
        P, a = data.levels
        y0 = jnp.where(a > 0, 1.0 / (jnp.pi * a.shape[0] * jnp.where(a > 0, a, 1.0)), 1.0)  # ρ̄d/π per channel

        def step(e, yd):
            y, d = e.unmeasure(vals[e.name], yd[0], ctx)
            return y, yd[1] * d

        yd = (jnp.broadcast_to(y0, data.y.shape), jnp.ones(data.y.shape))
        for e in reversed(effects):
            yd = _gated(_switch(active, e, "unmeasure"), lambda yd, e=e: step(e, yd), yd)
        w = jnp.where(data.mask, 1.0, 0.0)
        return jnp.maximum(jnp.sum(w * jnp.abs(yd[1])) / jnp.maximum(jnp.sum(w), 1.0), 1e-12)

    def predict(self, vals, active, effects, data):
        """Prediction of the measured values ``(S, N, C)``, profiled ρd ``(S, 1, C)``, censored mask."""
        ctx = self.context(data)
        r, f, rho, cens = self._profile(vals, active, effects, data, ctx)
        return f, rho, cens

    # ---------------------------------------------------------------- covariates
    def covariates(self, data: ScanlineData, pred: np.ndarray) -> dict[str, np.ndarray]:
        """Named covariates per observation ``(S, N, C)`` (NumPy), for structure tests and plots."""
        wi, wo = np.asarray(data.wi), np.asarray(data.wo)
        s, n, c = data.y.shape
        h = wi + wo
        hn = np.linalg.norm(h, axis=-1)
        hz = np.maximum(h[..., 2], 1e-12)
        out = {
            "theta_h": np.degrees(np.arctan2(np.hypot(h[..., 0], h[..., 1]), hz)),
            "half_azimuth": np.degrees(np.arctan2(h[..., 1], h[..., 0])),
            "theta_d": np.degrees(np.arccos(np.clip(np.sum(h * wi, -1) / hn, -1, 1))),
            "psi": np.degrees(np.arccos(np.clip(np.sum(wi * wo, -1), -1, 1))),
            "theta_i": np.degrees(np.arccos(np.clip(wi[..., 2], -1, 1))),
            "theta_o": np.degrees(np.arccos(np.clip(wo[..., 2], -1, 1))),
            "scanline": np.broadcast_to(np.arange(s, dtype=float)[:, None], (s, n)),
        }
        for k, v in data.cov.items():
            out[k] = np.asarray(v)
        out = {k: np.broadcast_to(v[..., None], (s, n, c)) for k, v in out.items()}
        p = np.asarray(pred)
        out["log_f"] = np.log(np.maximum(p, 1e-12) / data.f_std)
        if c > 1:
            out["channel"] = np.broadcast_to(np.arange(c, dtype=float), (s, n, c))
        return out


# ============================================================================ threshold model


@dataclasses.dataclass(frozen=True)
class ThresholdModel:
    """One straight line ``SD = a + b · PPB`` for every lightness (paper section 6, Fig. 8a)."""

    kind = "threshold"
    data_kinds = ("threshold",)
    library_kind = "threshold"
    title = "one PPB → lobe-SD line for all lightnesses"

    @staticmethod
    def supports(e) -> bool:
        """Whether the model implements ``e``'s forward change: every threshold effect."""
        return e.model == "threshold"

    def base_params(self, data: ThresholdData) -> tuple[Param, ...]:
        x, y, s = (np.asarray(a) for a in (data.ppb, data.sd, data.sigma))
        X = np.stack([np.ones_like(x), x], -1) / s[:, None]
        a, b = np.linalg.lstsq(X, y / s, rcond=None)[0]
        return (
            Param("a", float(a), scale=0.1, unit="deg", doc="intercept"),
            Param("b", float(b), scale=0.1, unit="deg/PPB", doc="slope"),
        )

    def n_profiled(self, data) -> int:
        return 0

    def _pred(self, vals, effects, data):
        base = vals["model"]
        slope = base["b"] * jnp.ones_like(data.ppb)
        for e in effects:
            slope = slope * e.slope_factor(vals[e.name], data)
        f = base["a"] + slope * data.ppb
        for e in effects:
            f = f + e.offset(vals[e.name], data)
        return f

    def residuals(self, vals, active, effects, data, ctx=None):
        return (data.sd - self._pred(vals, effects, data)) / data.sigma

    def predict(self, vals, active, effects, data):
        return self._pred(vals, effects, data), None, jnp.zeros(data.sd.shape, bool)

    def covariates(self, data: ThresholdData, pred) -> dict[str, np.ndarray]:
        ppb, rd = np.asarray(data.ppb), np.asarray(data.rho_d)
        return {"ppb": ppb, "rho_d": rd, "rho_d_x_ppb": (rd - rd.mean()) * ppb, "predicted_sd": np.asarray(pred)}
