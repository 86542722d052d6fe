"""The model's discrepancy in the parameters' σ, where discovery ends with a gap it cannot name.

Why
    A fit's σ say how well the data fix the parameters *if the model is
    right*. Where the final gap exceeds the noise and no library effect
    explains it (an "unexplained discrepancy"), the model is not right, and
    the part of the discrepancy that lies along the parameters' own
    directions is absorbed by them, unseen in the residuals: on the Radiance
    bench a second lamp left ρs 7 % low at z −150, a smudge 25 % low at z −300.

The discrepancy term (Kennedy & O'Hagan 2001, J. R. Stat. Soc. B 63, 425)
    The data are ``y = f(θ) + δ(x) + ε``. ``δ`` is taken constant over each of
    the quantile bins of a covariate along which the final whitened residuals
    show structure (the verdict's binned test, ``B`` bins; of those covariates
    the one that widens σ most, :func:`discrepancy`), the levels
    ``ξ ~ N(0, τ² K)`` with ``K_bb' = exp(−(x_b − x_b')²/2ℓ²)`` over the bins'
    ranks ``x_b = (b + ½)/B`` (``ℓ = 0``: independent levels, ``K = I``):
    ``δ = U ξ``, ``U`` the values' bin indicators ``(N, B)``. The fit absorbs
    part of it: the residuals are ``(1 − P)(ε + δ)``, ``P`` the
    projection on the whitened design (ρd's columns per scanline and the
    parameters' Jacobian ``J``), so the binned statistic
    ``T = Σ_b n_b r̄_b² = rᵀ U D⁻¹ Uᵀ r`` (``D`` the bins' counts) has

        E[T] = B − tr(D⁻¹ UᵀPU) + τ² tr(D⁻¹ G K G),   G = Uᵀ(1 − P)U,

    and by moments ``τ̂² = max(T − E₀, 0) / tr(D⁻¹ G K G)`` (``E₀`` the first
    two terms). Read without the absorption (``(T − B)/N``) τ came out half
    the truth on scanlines drawn with it. ``ℓ`` is the most likely of
    :data:`LENGTHS` for the bins' sums, ``Uᵀr ~ N(0, G + τ² G K G)`` with τ²
    profiled out (the hyperparameters estimated from the data, as Kennedy and
    O'Hagan do). The estimate moves by ``−H⁻¹ Jᵀ δ`` (``H⁻¹`` the fit's
    covariance, ``J`` the whitened residuals' Jacobian), so marginalised over
    ``δ`` its covariance gains

        ΔΣ = τ̂² gᵀ K g,   g_b = H⁻¹ Σ_{i ∈ b} J_iᵀ.

    The part of ``δ`` along the parameters, which the residuals cannot show,
    is sized by the prior from the part they do show: with independent levels
    no larger than that part; with correlated ones larger, as a smooth
    discrepancy lies largely along the parameters (levels drawn with
    ``ℓ = 1/8`` are read so, and z stays within ±4 where, read as
    independent, it goes beyond ±6). The report adds ``ΔΣ``'s σ to the model-averaged σ in
    quadrature.

What it cannot see
    A discrepancy whose every form the parameters absorb leaves no structure:
    room light in the lit frame alone scales the specular part of every ratio
    (``ρs`` 13 % low on the Radiance bench) and leaves a gap of 1.34 whose
    term leaves z at −20 to −32. One capture cannot identify it.
"""

from __future__ import annotations

import jax
import numpy as np

from ._models import _whitened_design
from ._report import FitState
from ._standard_sigma import whitened_jacobian
from ._step_record import flat as _flat
from ._structure import quantile_bins
from ._texture_term import is_identity_whitening

__all__ = ["LENGTHS", "bin_correlation", "discrepancy"]

# The prior's correlation lengths between the bins' levels, in shares of the covariate's range of ranks (0: the
# levels independent); the most likely one is taken (:func:`_correlation_length`).
LENGTHS = (0.0, 1 / 16, 1 / 8, 1 / 4, 1 / 2)


def _rho_d_basis(search) -> np.ndarray:
    """An orthonormal basis of ρd's whitened columns per scanline, ``Q`` ``(S, N C, C)`` with ``Q_s Q_sᵀ`` the
    projection on them (:func:`~wardjax.effects._models._whitened_design`; ``1/σ`` per channel under white
    noise): formed once per run, so that each covariate's share (:func:`_rho_d_share`) is sums only."""
    data, mask = search.data, np.asarray(search.mask)
    W = getattr(data, "whiten", None)
    if W is None or is_identity_whitening(np.asarray(W)):
        inv = np.where(mask, 1.0 / np.asarray(data.sigma), 0.0)
        X = inv[..., None] * np.eye(inv.shape[-1])[None, None]
    else:
        with jax.enable_x64(True):
            X = np.asarray(_whitened_design(data), np.float64)
    xs = X.reshape(X.shape[0], -1, X.shape[-1])
    lam, V = np.linalg.eigh(np.swapaxes(xs, 1, 2) @ xs)  # every scanline's C × C at once
    use = lam > 1e-12 * np.maximum(lam.max(-1, keepdims=True), 1e-300)  # a channel with no value: a zero column
    return xs @ (V * np.where(use, 1.0 / np.sqrt(np.where(use, lam, 1.0)), 0.0)[:, None, :])


def _rho_d_share(Q: np.ndarray, mask: np.ndarray, ok: np.ndarray, bins: np.ndarray, nb: int) -> np.ndarray:
    """``Uᵀ P_ρd U`` ``(B, B)``: the projection on ρd's whitened columns between the bins, ``Σ_s (U_sᵀQ_s)(U_sᵀQ_s)ᵀ``
    (``Q`` from :func:`_rho_d_basis`); ``ok`` flags which of the values at ``mask`` the ``bins`` index."""
    where = np.full(mask.shape, -1)
    flat_bins = np.full(int(mask.sum()), -1)
    flat_bins[ok] = bins
    where[mask] = flat_bins
    where = where.reshape(Q.shape[0], -1)
    s_idx, r_idx = np.nonzero(where >= 0)
    uq = np.zeros((Q.shape[0], nb, Q.shape[-1]))
    np.add.at(uq, (s_idx, where[s_idx, r_idx]), Q[s_idx, r_idx])
    return np.einsum("sbc,sdc->bd", uq, uq)


def discrepancy(search, st: FitState, r: np.ndarray, covs: dict[str, np.ndarray], structure: dict) -> dict | None:
    """The discrepancy term's reading for the final state ``st`` (fitted under ``search``): ``covariate``,
    ``bins``, ``tau`` (``τ̂``, in units of the noise σ), ``length`` (``ℓ``) and ``sigma`` (``{name: σ}`` the term
    adds to each of the model's own parameters); ``None`` where no covariate shows structure beyond its bins or
    no parameter is free.

    The term is read along every covariate whose binned χ² exceeds its bins in ``structure`` (the verdict's
    tests; ``readings``: each one's ``tau``, ``length``, ``lr`` — ``2 log Λ`` against no term — and ``widen``,
    ``Σ_p (σ_δ,p / σ_p)²`` over the model's parameters). One capture cannot say along which the discrepancy
    lies (a lamp's misfit shows against the half-vector, the intensity and the scanline alike), so the one
    that widens the parameters' σ most is taken.

    ``r``, ``covs``: the final whitened residuals and the covariates at the values of ``search.mask``, flat.
    """
    names = [k for k, v in structure.items() if k in covs and v["chi2"] > v["dof"]]
    if not names or not st.free:
        return None
    J = _flat(whitened_jacobian(search, st.u, st.free, st.active), search.mask)
    Q = _rho_d_basis(search)
    free = list(st.free)
    cov_b = np.asarray(st.cov)[np.ix_(free, free)]
    got = {
        k: x for k in names if (x := _reading(search, st, r, J, Q, cov_b, covs[k], structure[k]["chi2"])) is not None
    }
    if not got:
        return None
    own = search.layout.sigma(st.u, np.asarray(st.cov))["model"]
    sig = {k: dict(search.layout.sigma(st.u, x[4])["model"]) for k, x in got.items()}
    widen = {k: float(sum((v / own[p]) ** 2 for p, v in s_.items() if own.get(p, 0) > 0)) for k, s_ in sig.items()}
    name = max(widen, key=lambda k: widen[k])
    _, nb, tau2, ell, _ = got[name]
    return {
        "covariate": name,
        "bins": nb,
        "tau": float(np.sqrt(tau2)),
        "length": ell,
        "sigma": sig[name],
        "readings": {
            k: {"tau": float(np.sqrt(x[2])), "length": x[3], "lr": x[0], "widen": widen[k]} for k, x in got.items()
        },
    }


def _reading(
    search, st: FitState, r: np.ndarray, J: np.ndarray, Q: np.ndarray, cov_b: np.ndarray, x: np.ndarray, chi2: float
):
    """The term along one covariate ``x`` (flat, as ``r``) whose binned statistic is ``chi2``: ``(likelihood ratio,
    bins, τ̂², ℓ, ΔΣ)``, or ``None`` where no value has both. ``J``: the whitened Jacobian at the values of
    ``search.mask``, flat; ``Q``: ρd's whitened basis (:func:`_rho_d_basis`); ``cov_b``: the free parameters'
    covariance."""
    ok = np.isfinite(r) & np.isfinite(x)
    if not ok.any():
        return None
    bins, nb = quantile_bins(x[ok])
    uj = np.stack([np.bincount(bins, weights=J[ok, j], minlength=nb) for j in range(J.shape[1])], 1)  # UᵀJ (B, K)
    g = uj @ cov_b  # (B, K): H⁻¹ Jᵀ summed over each bin
    upu = uj @ g.T + _rho_d_share(Q, np.asarray(search.mask), ok, bins, nb)
    counts = np.bincount(bins, minlength=nb).astype(float)
    keep = counts > 0
    gram = np.diag(counts) - upu  # G = Uᵀ(1 − P)U
    e0 = keep.sum() - float(np.sum(np.diag(upu)[keep] / counts[keep]))
    ell, lr = _correlation_length(np.bincount(bins, weights=r[ok], minlength=nb), gram)
    K = bin_correlation(nb, ell)
    w = gram[keep] / np.sqrt(counts[keep, None])  # D^{−½} G
    size = float(np.sum((w @ K) * w))  # tr(D⁻¹ G K G)
    tau2 = max(chi2 - e0, 0.0) / max(size, 1e-300)
    cov = np.zeros_like(np.asarray(st.cov))
    cov[np.ix_(st.free, st.free)] = tau2 * g.T @ K @ g
    return lr, nb, tau2, ell, cov


def bin_correlation(nb: int, ell: float) -> np.ndarray:
    """The bins' prior correlation ``K`` ``(B, B)``: ``exp(−(x_b − x_b')² / 2ℓ²)`` over the bins' centres in rank,
    ``x_b = (b + ½)/B`` (quantile bins: equal shares of the values); ``ℓ = 0``: independent levels, ``K = I``."""
    if ell <= 0:
        return np.eye(nb)
    x = (np.arange(nb) + 0.5) / nb
    return np.exp(-0.5 * ((x[:, None] - x[None, :]) / ell) ** 2)


def _correlation_length(z: np.ndarray, gram: np.ndarray) -> tuple[float, float]:
    """The correlation length of :data:`LENGTHS` under which the binned residual sums ``z = Uᵀr`` ``(B,)`` are most
    likely, τ² profiled out: ``z ~ N(0, G + τ² G K G)`` (``G = Uᵀ(1 − P)U``; the noise's part and the discrepancy's
    part the fit leaves), both restricted to the range of ``G`` (what the fit absorbs is zero in ``z``). Returns
    ``(ℓ, 2 log Λ)``, ``Λ`` the likelihood ratio of that term against none (``τ = 0``)."""
    lam, V = np.linalg.eigh(gram)
    use = lam > 1e-9 * max(float(lam.max()), 1e-300)
    lam, V = lam[use], V[:, use]
    zt = V.T @ z
    null = 0.5 * (float(np.sum(zt**2 / lam)) + float(np.sum(np.log(lam))))
    best = (-np.inf, 0.0)
    for ell in LENGTHS:
        M = (lam[:, None] * (V.T @ bin_correlation(len(z), ell) @ V)) * lam[None, :]

        def nll(log_t2, M=M):
            C = np.diag(lam) + np.exp(log_t2) * M
            sign, logdet = np.linalg.slogdet(C)
            return np.inf if sign <= 0 else 0.5 * (zt @ np.linalg.solve(C, zt) + logdet)

        grid = np.linspace(-12.0, 12.0, 49)
        vals = [nll(t) for t in grid]
        i = int(np.argmin(vals))
        fine = np.linspace(grid[max(i - 1, 0)], grid[min(i + 1, len(grid) - 1)], 21)
        ll = -min(nll(t) for t in fine)
        if ll > best[0] + 1e-9:
            best = (ll, ell)
    return best[1], 2.0 * max(best[0] + null, 0.0)
