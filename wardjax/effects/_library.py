"""The effect library: measurement side, material side, threshold data.

Each class documents its forward change (the maths the hooks implement), its
parameters, the residual signature (telling covariate) and the source. The
scanline hooks act on the Ward prediction in this order (see
:mod:`wardjax.effects._models`): lobe shape → specular factor → per-channel
ρs → extra additive terms → measurement transforms (in library order) →
censoring. At their absent values every hook is the identity.
"""

from __future__ import annotations

import math

import jax.numpy as jnp
import numpy as np

from ._effect import Effect, Param
from ._models import _lobe
from ._pixel_levels import encoding_from_ratio, encoding_to_ratio

__all__ = ["LIBRARY", "library", "get_effect"]


class _ScanlineEffect(Effect):
    model = "scanline"

    def lobe(self, v, ax, ay, phi):
        return ax, ay, phi

    def spec_factor(self, v, ctx):
        return 1.0

    def rho_s_factor(self, v, c):
        return 1.0

    def extra(self, v, ctx, base, ax, ay, phi):
        return 0.0

    def measure(self, v, f, ctx):
        return f

    def unmeasure(self, v, y, ctx):
        """Inverse of :meth:`measure` and its derivative ``d f / d y``."""
        return y, 1.0

    censors = False

    def censored(self, active, data):
        return False


class _ThresholdEffect(Effect):
    model = "threshold"
    side = "threshold"

    def slope_factor(self, v, data):
        return 1.0

    def offset(self, v, data):
        return 0.0


# ============================================================================ measurement side


class Saturation(_ScanlineEffect):
    """Sensor saturation: clipped highlights, fitted with the censored likelihood.

    Physics: a pixel value cannot exceed the sensor's full well / white level
    ``v_max``. In the ratio ``v/v_std`` the probe is clipped and the standard
    (a diffuse white, far below ``v_max``) is not, so ``f_meas = min(f, c_n)``
    with ``c_n = v_max/(k E_n)`` ∝ ``r²/cos θi`` (the lamp irradiance ``E``);
    without lamp geometry ``c_n`` is a constant per channel. The image-based
    paper names it as a limitation of the method (section 4.1: "artifacts due
    to saturation of the camera").

    Fit: the clipped observations are *censored*: they say only
    ``value ≥ y``, and contribute ``−2 log Φ((f − y)/σ)`` to the deviance
    instead of ``((y − f)/σ)²`` (the censored, Tobit, likelihood), so a
    clipped highlight still bounds ρs and α from below rather than being
    dropped. Which values are clipped: the data's ``censored`` flags where
    the sensor reports them (:func:`~wardjax.effects.scanline_data`), else
    the values whose ``y / (r²/cos θi)`` ties with the channel maximum, the
    clip level then estimated from the data (the maximum), counted as one
    parameter in the evidence either way.

    Signature: negative residuals of the unclipped model at the highest
    predicted intensities, and clipped values (it is only tested when the
    data flag some as censored, or at least three tie at a channel's
    maximum).
    """

    name = "saturation"
    title = "sensor saturation (clipped highlights)"
    side = "measurement"
    covariate = "log_f"
    n_data_params = 1
    censors = True

    def _z(self, data):
        y = jnp.asarray(data.y)
        if "inv_irradiance" in data.cov:
            y = y / data.cov["inv_irradiance"][..., None]
        return y

    def applicable(self, data):
        why = super().applicable(data)
        if why:
            return why
        if data.censored is not None:
            if np.any(np.asarray(data.censored)):
                return None
            return "no value is flagged as clipped"
        z = np.asarray(self._z(data))
        m = np.asarray(data.mask)
        zm = np.where(m, z, -np.inf)
        top = zm.max(axis=(0, 1))
        ties = np.sum(m & (z >= top * (1 - 1e-9)), axis=(0, 1))
        if np.max(ties) < 3:
            return "no plateau of tied maximum values (fewer than 3 per channel)"
        return None

    def censored(self, active, data):
        if data.censored is not None:
            return active & data.mask & data.censored
        z = self._z(data)
        zm = jnp.where(data.mask, z, -jnp.inf)
        top = jnp.max(zm, axis=(0, 1), keepdims=True)
        return active & data.mask & (z >= top * (1 - 1e-9))


class AmbientOffset(_ScanlineEffect):
    """Ambient light not removed (or changed between the lit and dark frames).

    Physics: an ambient radiance ``A`` adds to probe and standard alike, so the
    ratio becomes (image-based paper, reconstruction equation, with
    ``v_background`` not cancelling ``A``)::

        f_meas = f_std · (E f + A) / (E f_std + A) = f_std · (f + a w) / (f_std + a w)

    with ``w = Ē / E ∝ r²/cos θi`` (mean 1) and ``a = A/Ē`` in sr⁻¹. A
    constant offset would be absorbed by ρd; what gives it away is that its
    weight follows the *inverse lamp irradiance* along the scanline, and that
    it pulls highlights towards ``f_std``. ``a`` may have either sign
    (light added, or the dark frame taken under more ambient light).
    """

    name = "ambient"
    title = "ambient light not removed / changed between frames"
    side = "measurement"
    covariate = "inv_irradiance"
    requires = ("inv_irradiance",)
    params = (Param("a", 0.0, scale=0.02, unit="sr⁻¹", doc="ambient / mean lamp irradiance"),)

    def measure(self, v, f, ctx):
        aw = v["a"] * ctx["inv_irradiance"][..., None]
        return ctx["f_std"] * (f + aw) / (ctx["f_std"] + aw)

    def unmeasure(self, v, y, ctx):
        aw = v["a"] * ctx["inv_irradiance"][..., None]
        k = (ctx["f_std"] + aw) / ctx["f_std"]
        return y * k - aw, k


class VeilingGlare(_ScanlineEffect):
    """Veiling glare: light the lens spreads over the frame, added to probe and standard alike.

    Physics: stray light inside the lens adds to every pixel of the lit frame
    a veil ``c`` and a share ``g`` of the frame itself spread wide, ``B`` (the
    lit frame blurred by a Gaussian of :data:`~wardjax.effects._pixel_levels.GLARE_WIDTH`
    of the image width); the dark frame, without the lamp, has almost none. With
    the levels behind each ratio value (:func:`~wardjax.effects._pixel_levels.pixel_levels`:
    ``B`` at the probe pixel ``B_p`` and at the standard's mirror pixel ``B_q``,
    the standard's lit-minus-dark level ``span``), the ratio
    ``f_std (L_p − D_p)/(L_q − D_q)`` becomes::

        f_meas = (f + f_std (c + g B_p)/span) / (1 + (c + g B_q)/span)

    The veil alone is :class:`AmbientOffset` (a level over the standard's span
    follows the lamp's inverse irradiance); the blurred share is largest beside
    the highlight and on the bright standard, where a constant is not: it lowers
    the lobe against the diffuse floor and widens it. Signature: residuals
    against ``log f`` (the darks lifted most, relative to their level).

    Only one width is tried: a lens whose glare spreads much wider or narrower
    is read partly as the veil. The Radiance bench draws glare of this width.
    """

    name = "glare"
    title = "veiling glare (a veil and a share of the lit frame spread wide)"
    nests = ("ambient", ("g",))
    side = "measurement"
    covariate = "log_f"
    requires = ("glare",)
    params = (
        Param("c", 0.0, scale=0.005, doc="veil: a level added to the lit frame everywhere (full scale 1)"),
        Param("g", 0.0, scale=0.02, sign=1, doc="share of the lit frame, blurred wide, added to it"),
    )

    @staticmethod
    def _added(v, ctx):
        """What the glare adds to the ratio's numerator, ``f_std (c + g B_p)/span``, and denominator, ``1 + (c + g
        B_q)/span``."""
        span = ctx["lit_std"] - ctx["dark_std"]
        add_p, add_q = v["c"] + v["g"] * ctx["glare_probe"], v["c"] + v["g"] * ctx["glare_std"]
        return ctx["ref"] * add_p / span, 1.0 + add_q / span

    def measure(self, v, f, ctx):
        top, k = self._added(v, ctx)
        return (f + top) / k

    def unmeasure(self, v, y, ctx):
        top, k = self._added(v, ctx)
        return y * k - top, k


class GammaMismatch(_ScanlineEffect):
    """Camera response other than assumed (γ mismatch).

    Physics: decoding with γ_assumed an image encoded with γ_true leaves
    ``v_lin = L^{γ_true/γ_assumed} = L^{1+ε}``; the ratio of two such values
    is the ratio of the radiances raised to ``1+ε``, so (exposure cancels)::

        f_meas = f_std · (f / f_std)^{1+ε}

    The rig's symmetry does not remove it: it bends the response about the
    standard's level. The smartphone paper assumes γ = 2.2 (section 3.1).
    Signature: residuals linear in ``log f`` (predicted intensity).
    """

    name = "gamma"
    title = "camera response other than assumed (γ mismatch)"
    side = "measurement"
    covariate = "log_f"
    params = (Param("eps", 0.0, scale=0.05, doc="γ_true/γ_assumed − 1"),)

    def measure(self, v, f, ctx):
        fs = ctx["f_std"]
        return fs * jnp.exp((1.0 + v["eps"]) * jnp.log(jnp.maximum(f, 1e-12) / fs))

    def unmeasure(self, v, y, ctx):
        fs = ctx["f_std"]
        p = 1.0 / (1.0 + v["eps"])
        f = fs * jnp.exp(p * jnp.log(jnp.maximum(y, 1e-12) / fs))
        return f, p * f / jnp.maximum(y, 1e-12)


class EncodingMismatch(_ScanlineEffect):
    """Image encoding other than declared: sRGB and the pure power 2.2 taken for each other.

    Physics: the two encodings agree within a few per cent in the mid-tones
    and part in the darks, where sRGB has a linear toe (``12.92 x`` below
    0.0031308) and the power law none. Files written as ``v^{1/2.2}`` and
    declared sRGB decode each code ``c`` to ``sRGB⁻¹(c)`` instead of
    ``c^{2.2}``: with ``E`` the declared encoding and ``D'`` the other one's
    decoding, the true linear level of a decoded level ``L`` is
    ``h(L) = D'(E(L))``. A share ``t`` of it::

        g_t(L) = (1 − t) L + t h(L)

    enters the ratio through every pixel level, lit and dark, probe and
    standard (:mod:`~wardjax.effects._pixel_levels`, where ``h`` is evaluated
    once per value, so that the effect is linear in ``t``); ``t = 1`` is the
    other encoding exactly, ``t = 0`` the declared one. A γ mismatch (a power of
    every level) cannot take its place: the difference bends the darks up
    (+2 % at 1 % of full scale above a 2 % dark frame) and the mid-tones down
    (−1.3 % at 10–20 %), an S in ``log f`` that neither a power nor an ambient
    offset follows. Needs the pixel levels and an encoding with an
    alternative (``srgb`` or ``gamma2.2``; a linear file has none).
    Signature: residuals against ``log f``, S-shaped.
    """

    name = "encoding"
    title = "image encoding other than declared (sRGB ↔ power 2.2)"
    side = "measurement"
    covariate = "log_f"
    requires = ("encoding_alternative",)
    params = (Param("t", 0.0, scale=0.5, sign=1, doc="share of the other encoding (1: wholly the other)"),)

    def measure(self, v, f, ctx):
        return encoding_from_ratio(v["t"], f, ctx)

    def unmeasure(self, v, y, ctx):
        return encoding_to_ratio(v["t"], y, ctx)


class IlluminationGradient(_ScanlineEffect):
    r"""Non-uniform illumination or vignetting that breaks the probe/standard symmetry.

    Physics: a multiplicative field ``G`` on the lit frame (a lamp off the
    symmetry plane, a lens's falloff centred off the stripline, a ramp across
    the image) scales the probe pixel ``p`` and the pixel of its mirror point
    ``p' = (−x, y)`` on the standard differently. The reconstruction divides
    the two (image-based paper, eq. "f_r,measured"), so what survives is::

        f_meas = f · G(p) / G(p')

    Write ``log G`` to first order in the coordinates ``(s, t)`` of the point —
    in the image, ``s = (u − c_u)/W``, ``t = (v − c_v)/W`` from the principal
    point ``(c_u, c_v)`` and the image width ``W`` when the data carry the
    camera (:func:`~wardjax.effects.scanline_data`, ``camera=``); else on the
    sample plane, ``s = x/L``, ``t = y/L`` with ``L`` = 100 mm — with the cross
    term that a tilted field needs::

        log G(q) = b₀ + b_s s + b_t t + b_st s t
        log f_meas − log f = b_s Δs + b_st Δ(st)         (Δ· = ·(p) − ·(p'))

    ``b₀`` cancels, and ``b_t Δt`` vanishes in the paper's rig (camera and lamp
    in the symmetry plane map ``p'`` to the mirror pixel, ``t(p') = t(p)``,
    ``s(p') = −s(p)``), so ``Δs = 2 s(p)``, ``Δ(st) = 2 s t``. A ramp across
    the image columns, ``G = 1 + g s``, gives ``b_s = g`` to first order and a
    factor **constant along each scanline** (a scanline is an image column):
    the per-scanline ρd absorbs it on the diffuse term, and what remains is the
    specular amplitude trending across scanlines with ``s`` — at a fixed
    half-vector azimuth, not following it (anisotropy follows the azimuth). On
    the sample plane a column is not a line of constant ``x`` (perspective:
    ``x ∝ s · depth(y)``), which is why an ``x``-only factor, varying along
    each scanline, missed the image ramp on the diffuse term. ``b_st`` (a field
    tilted across the image, or a lamp off the plane, whose
    ``log E(p)/E(p') ∝ x/r²`` falls along the scanline) moves the diffuse level
    along each scanline in proportion to ``s``.

    Signature: residuals against ``s`` (the image column); covariate ``x``.
    """

    name = "illumination_gradient"
    title = "illumination / vignetting asymmetric about the stripline"
    side = "measurement"
    covariate = "x"
    requires = ("illum_s", "illum_st")
    params = (
        Param("b", 0.0, scale=0.1, doc="log-gradient of the field across the stripline (per image width or 100 mm)"),
        Param("b_st", 0.0, scale=0.3, optional=True, doc="cross term s·t of the field's log (tilt)"),
    )

    def _log_factor(self, v, ctx):
        return (v["b"] * ctx["illum_s"] + v["b_st"] * ctx["illum_st"])[..., None]

    def measure(self, v, f, ctx):
        return f * jnp.exp(self._log_factor(v, ctx))

    def unmeasure(self, v, y, ctx):
        k = jnp.exp(-self._log_factor(v, ctx))
        return y * k, k


class SymmetricFalloff(_ScanlineEffect):
    """Lamp falloff / vignetting symmetric about the stripline — cancels from v/v_std.

    Physics: ``f_meas = f · G(p)/G(p')`` with ``G(p) = G(p')`` for a field even
    in ``x`` (the lamp's ``1/r²`` and cos θ falloff with the lamp in the
    symmetry plane, vignetting centred on the stripline): the factor is 1 and
    the effect is *not detectable* from reconstructed BRDFs (DESIGN.md,
    "Missing effects"; image-based paper section 3: "a symmetric
    distribution of light source radiation is necessary"). On radiance data
    (no standard) it would be ``f · (1 + v r²/L²)`` against image radius.
    """

    name = "symmetric_falloff"
    title = "lamp falloff / vignetting symmetric about the stripline"
    side = "measurement"
    covariate = "radius"
    requires = ("radius",)
    cancels_by_symmetry = True
    params = (Param("v", 0.0, scale=0.1, doc="radial falloff coefficient"),)

    def measure(self, v, f, ctx):
        return f * (1.0 + v["v"] * ctx["radius"][..., None] ** 2)

    def unmeasure(self, v, y, ctx):
        k = 1.0 / (1.0 + v["v"] * ctx["radius"][..., None] ** 2)
        return y * k, k


class DirectionalEmission(_ScanlineEffect):
    """Directional emission of the light source (the phone screen of the smartphone paper).

    Physics: the emitted intensity falls off with the angle ``β`` from the
    emitter's axis, ``I(β) ∝ cos^n β`` (smartphone paper, section 8: "light
    emission from the iPhone screen was quite directional"; Fig. 10). In the
    image-based rig the lamp lies in the symmetry plane, ``β(p) = β(p')``, and
    the factor cancels from ``v/v_std``: *not detectable* from reconstructed
    BRDFs. On radiance data it is ``f · cos^n β`` against ``β`` for one
    source per observation (:meth:`measure`), and ``cos^n θe,k`` on each of
    an extended source's cells ``k`` (:meth:`source_factor`) — a phone
    screen reflected in a sample (:class:`~wardjax.effects.ScreenModel`),
    where the light reaching one pixel leaves the screen over a wide range
    of angles, so no single ``β`` per pixel stands for it.
    """

    name = "directional_emission"
    title = "directional emission of the light source (phone screen)"
    side = "measurement"
    covariate = "emission_angle"
    requires = ("emission_angle",)
    cancels_by_symmetry = True
    params = (Param("n", 0.0, scale=1.0, doc="cos^n exponent"),)

    def measure(self, v, f, ctx):
        return f * jnp.cos(ctx["emission_angle"][..., None]) ** v["n"]

    def unmeasure(self, v, y, ctx):
        k = jnp.cos(ctx["emission_angle"][..., None]) ** (-v["n"])
        return y * k, k

    def source_factor(self, v, ctx):
        """``cos^n θe`` per observation and source cell (``ctx["cos_emit"]``, > 0 where a cell lights a point)."""
        return ctx["cos_emit"] ** v["n"]


# ============================================================================ material side


class FresnelRise(_ScanlineEffect):
    """Fresnel rise of the specular reflectance toward grazing (Schlick's form).

    Physics: ``ρs`` is the Fresnel reflectance, which rises toward grazing
    (smartphone paper, Fig. 4 and section 3.3); with Schlick's approximation
    ``F(θd) = F0 + (1 − F0)(1 − cos θd)^5`` about the half vector, relative to
    ``F0``::

        S → S · (1 + κ (1 − cos θd)^5),   κ = (1 − F0)/F0 ≥ 0

    (κ ≈ 24 for a dielectric with n = 1.5). Signature: residuals against
    θd, the angle between the half vector and the light.
    """

    name = "fresnel"
    title = "Fresnel rise toward grazing"
    side = "material"
    covariate = "theta_d"
    params = (Param("kappa", 5.0, scale=10.0, sign=+1, starts=(40.0,), doc="(1 − F0)/F0"),)

    def spec_factor(self, v, ctx):
        return 1.0 + v["kappa"] * (1.0 - ctx["cos_d"]) ** 5


class Anisotropy(_ScanlineEffect):
    """Anisotropy: αx ≠ αy with an orientation φ of the tangent.

    Physics: the anisotropic Ward lobe (image-based paper, K for the
    anisotropic case) with ``αx = α e^{η}``, ``αy = α e^{−η}`` and the tangent
    frame turned by φ about the normal. Absent at ``η = 0`` (φ then has no
    effect; it is started at four orientations). Signature: residuals against
    the half-vector azimuth.
    """

    name = "anisotropy"
    title = "anisotropy (αx ≠ αy, with orientation)"
    side = "material"
    covariate = "half_azimuth"
    params = (
        Param("eta", 0.15, scale=0.2, doc="½ log(αx/αy)"),
        Param(
            "phi",
            0.0,
            absent=math.nan,
            scale=1.0,
            starts=(math.pi / 4, math.pi / 2, -math.pi / 4),
            unit="rad",
            doc="tangent orientation",
            prior_sd=3.0,
        ),
    )

    def lobe(self, v, ax, ay, phi):
        return ax * jnp.exp(v["eta"]), ay * jnp.exp(-v["eta"]), phi + v["phi"]


class SecondLobe(_ScanlineEffect):
    """Off-specular peak / second specular lobe.

    Physics: layered finishes (clear coat over a rough base) and surfaces with
    a haze show two lobes; a low-gloss surface's lobe peaking off the mirror
    direction (smartphone paper, section 9.2: measured lobes "peak at
    approximately 17–18°, showing the off-specular characteristic") is, to
    the resolution of these data, a second, wider lobe beside the first::

        f += q ρs S(h; α2, α2),  α2 = α e^{ℓ},  q ≥ 0

    Signature: residuals against the half-angle θh.
    """

    name = "second_lobe"
    title = "off-specular peak / second specular lobe"
    side = "material"
    covariate = "theta_h"
    params = (
        Param("q", 0.3, scale=0.3, sign=+1, doc="second-lobe ρs / first-lobe ρs"),
        Param(
            "log_ratio",
            math.log(3.0),
            absent=math.nan,
            scale=1.0,
            starts=(-math.log(3.0),),
            doc="log(α2/α)",
            prior_sd=2.0,
        ),
    )

    def extra(self, v, ctx, base, ax, ay, phi):
        a2 = base["alpha"] * jnp.exp(v["log_ratio"])
        return (v["q"] * base["rho_s"] * _lobe(ctx, a2, a2, 0.0))[..., None]


class ColouredSpecular(_ScanlineEffect):
    """Coloured specular reflectance (metals): ρs per RGB channel.

    Physics: metals reflect selectively, so ``ρs`` is an RGB triple
    (smartphone paper, section 2: "For metallic surfaces ρs is also an RGB
    triple"; :func:`wardjax.specular_rgb_metal`)::

        ρs,c = ρs · exp(t_c),  t_G = 0

    Signature: the highlight residuals differ between channels (covariate:
    channel).
    """

    name = "coloured_specular"
    title = "coloured specular (metals)"
    side = "material"
    covariate = "channel"
    requires = ("rgb",)
    params = (Param("t_r", 0.0, scale=0.2, doc="log(ρs,R/ρs,G)"), Param("t_b", 0.0, scale=0.2, doc="log(ρs,B/ρs,G)"))

    def rho_s_factor(self, v, c):
        if c != 3:
            return 1.0
        return jnp.exp(jnp.stack([v["t_r"], 0.0 * v["t_r"], v["t_b"]]))


class Retroreflection(_ScanlineEffect):
    """Retroreflection: a back-scatter lobe around ``wo = wi``.

    Physics: rough, porous and beaded surfaces return light toward the source
    (the opposition effect); a Gaussian lobe in the angle ψ between the
    directions to light and camera::

        f += A exp(−ψ² / (2 β²)),  A ≥ 0

    Signature: residuals against ψ.
    """

    name = "retroreflection"
    title = "retroreflection (back-scatter lobe)"
    side = "material"
    covariate = "psi"
    params = (
        Param("amp", 0.01, scale=0.02, sign=+1, unit="sr⁻¹", doc="retro-lobe peak"),
        Param(
            "width",
            0.5,
            absent=math.nan,
            kind="log",
            scale=0.5,
            starts=(0.25, 1.0),
            unit="rad",
            doc="retro-lobe angular SD",
            prior_sd=2.0,
        ),
    )

    def extra(self, v, ctx, base, ax, ay, phi):
        return (v["amp"] * jnp.exp(-0.5 * (ctx["psi"] / v["width"]) ** 2))[..., None]


# ============================================================================ threshold data


class ContrastGloss(_ThresholdEffect):
    """Contrast gloss: the diffuse floor lowers the reflected grating's contrast.

    Physics (smartphone paper, section 6, Fig. 8a): the reflected grating's
    contrast is ``C = S/(S + D)`` with a diffuse floor ``D ∝ ρd``; a lower
    contrast reaches the visibility threshold at a coarser grating, so the
    PPB → SD line is *shallower for lighter surfaces* — "differing slopes"
    that the paper interprets as contrast gloss::

        SD = a + b · exp(c (ρd − ρ̄d)) · PPB,  c ≤ 0

    Signature: residuals against ``(ρd − ρ̄d) · PPB``.
    """

    name = "contrast_gloss"
    title = "contrast gloss (diffuse floor lowers reflected contrast)"
    covariate = "rho_d_x_ppb"
    params = (Param("c", -0.1, scale=0.3, sign=-1, doc="d log(slope) / d ρd"),)

    def slope_factor(self, v, data):
        rd = data.rho_d - jnp.mean(data.rho_d)
        return jnp.exp(v["c"] * rd)


class LobeFloor(_ThresholdEffect):
    """A diffuse pedestal left in the glossmeter's lobe SD.

    Physics: the paper subtracts each lobe's minimum before computing its SD
    (section 4); a pedestal left over widens the computed SD of lighter
    surfaces (more diffuse light), adding ``e (ρd − ρ̄d)`` with ``e ≥ 0``
    regardless of the grating. Signature: residuals against ρd.
    """

    name = "lobe_floor"
    title = "diffuse pedestal left in the measured lobe SD"
    covariate = "rho_d"
    params = (Param("e", 0.1, scale=0.3, sign=+1, unit="deg", doc="SD added per unit ρd"),)

    def offset(self, v, data):
        return v["e"] * (data.rho_d - jnp.mean(data.rho_d))


class PPBCurvature(_ThresholdEffect):
    """Curvature of the PPB → SD relation (the CSF's shape across frequency).

    Physics: the threshold condition ``C · MTF(f; SD) = 1/CSF(f)`` gives a
    straight line only where the CSF is flat in log; its curvature bends the
    line, ``+ c2 · PPB²``. Signature: residuals against PPB.
    """

    name = "ppb_curvature"
    title = "curvature of the PPB → SD line (CSF shape)"
    covariate = "ppb"
    params = (Param("c2", 0.0, scale=0.001, unit="deg/PPB²", doc="quadratic coefficient"),)

    def offset(self, v, data):
        return v["c2"] * data.ppb**2


LIBRARY: tuple[Effect, ...] = (
    Saturation(),
    AmbientOffset(),
    VeilingGlare(),
    GammaMismatch(),
    EncodingMismatch(),
    IlluminationGradient(),
    SymmetricFalloff(),
    DirectionalEmission(),
    FresnelRise(),
    Anisotropy(),
    SecondLobe(),
    ColouredSpecular(),
    Retroreflection(),
    ContrastGloss(),
    LobeFloor(),
    PPBCurvature(),
)


def library(model: str | None = None) -> tuple[Effect, ...]:
    """The library's effects, optionally only those extending ``model`` (``"scanline"``/``"threshold"``)."""
    if model is not None and model not in ("scanline", "threshold"):
        raise ValueError(f"model must be 'scanline' or 'threshold', got {model!r}")
    return tuple(e for e in LIBRARY if model is None or e.model == model)


def get_effect(name: str) -> Effect:
    """The library effect called ``name``."""
    for e in LIBRARY:
        if e.name == name:
            return e
    raise ValueError(f"no effect named {name!r}; the library has {', '.join(e.name for e in LIBRARY)}")
