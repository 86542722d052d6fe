"""Held-out-photo error of a mixture of lobes: each photo predicted from a pixel's other photos.

A count of clusters must predict photos it was not fitted to, the measure
multi-view captures are compared by. For pixel ``p``, lobe ``l`` and photo
``j`` the pixel's ρd is fitted to its other photos only (linear, closed form),
and the pixel takes the lobe that fits those photos best,
``argmin_l χ²_{pl}(−j) − 2 log π_l``; photo ``j`` is then predicted. With
``r_k = f_k − s_l B_k`` (:mod:`._pixel_model`) and the weighted sums
``S_rr = Σ_k w r²``, ``S_qr = Σ_k w q r``, ``S_qq = Σ_k w q²`` per channel,
leaving photo ``j`` out subtracts its term from each sum (``S'``), and

.. math::

    a_{−j} = S'_{qr}/S'_{qq},\\qquad χ²_{pl}(−j) = Σ_c S'_{rr} − S'^2_{qr}/S'_{qq},\\qquad
    e_{plj} = Σ_c w_j (r_j − q_j a_{−j})^2

(leave-one-out cross-validation of the linear part, Hastie, Tibshirani &
Friedman §7.10). The score is ``Σ_{p,j} e_{p l_j(p) j}``. The lobes themselves
are fitted to every photo: each is shared by many pixels, so what one photo
of one pixel tells it is small; a pixel's choice of lobe is its own, and that
is what a bump's highlight can buy and a held-out photo then refuses.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from . import _pixel_model as pm

__all__ = ["heldout_chi2"]


@jax.jit
def heldout_chi2(theta, s, log_pi, geom: pm.PixelGeometry, f, w):
    """The held-out χ² (module docstring) of lobes ``theta (L, d)``, ``s (L,)`` with shares ``log_pi (L,)``,
    and the number of values it predicts (0 where no pixel has a second usable photo: nothing is held out)."""
    q = geom.q[..., None]  # (P, K, 1)
    wq = w * q

    def one(ts):
        t, s_l = ts
        b = pm.basis(geom, jnp.broadcast_to(t, (f.shape[0], t.shape[-1])))
        r = f - s_l * b[..., None]  # (P, K, C)
        s_rr, s_qr, s_qq = (jnp.sum(x, 1, keepdims=True) for x in (w * r * r, wq * r, wq * q))
        rr, qr, qq = s_rr - w * r * r, s_qr - wq * r, s_qq - wq * q
        ok = qq > 0
        safe = jnp.where(ok, qq, 1.0)
        a = jnp.where(ok, qr / safe, 0.0)
        chi2 = jnp.sum(jnp.where(ok, rr - qr * qr / safe, 0.0), -1)  # (P, K)
        err = jnp.sum(jnp.where(ok, w * (r - q * a) ** 2, 0.0), -1)  # (P, K)
        return chi2, err, jnp.sum(ok & (w > 0))

    chi2, err, n = jax.lax.map(one, (theta, s))  # (L, P, K) each, and (L,)
    label = jnp.argmin(chi2 - 2.0 * log_pi[:, None, None], 0)  # (P, K)
    return jnp.sum(jnp.take_along_axis(err, label[None], 0)), n[0]
