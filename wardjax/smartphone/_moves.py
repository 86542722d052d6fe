"""Block-diagonal emcee moves for many independent posteriors run in lock step.

emcee's stretch and differential-evolution moves mix all walkers of an
ensemble. When one ensemble holds the walkers of ``B`` independent problems
(:func:`~wardjax.smartphone.alpha_posterior_batch`), each problem's walkers
must only ever be proposed from their own block: these moves apply emcee's
proposals block by block.
"""

from __future__ import annotations

import emcee
import numpy as np

__all__ = ["block_moves"]


class _BlockMove(emcee.moves.Move):
    """An ensemble move run independently in ``n_blocks`` blocks of walkers.

    Walker rows ``[b·W, (b+1)·W)`` form block ``b``. Each block is split into two random
    halves of ``W/2``; each half is updated against the other half of the *same* block,
    exactly as emcee's red-blue moves do for one ensemble. The log-probability receives
    the proposals of one half of every block, block by block, so it can tell blocks apart
    from the row index alone; it is called directly (vectorised), without emcee's
    per-walker conversion loop, and NaN is refused as emcee does.
    """

    def __init__(self, n_blocks: int):
        self.n_blocks = int(n_blocks)

    def _proposal(self, s, c, rng):  # (nb, h, d), (nb, h, d) -> q, log-factors (nb, h)
        raise NotImplementedError

    def propose(self, model, state):
        n, d = state.coords.shape
        nb = self.n_blocks
        w = n // nb
        h = w // 2
        rng = model.random
        coords = state.coords.copy()
        log_prob = state.log_prob.copy()
        accepted = np.zeros(n, dtype=bool)
        perm = np.argsort(rng.rand(nb, w), axis=1) + (np.arange(nb) * w)[:, None]
        halves = (perm[:, :h], perm[:, h:])
        for split in (0, 1):
            s_idx, c_idx = halves[split], halves[1 - split]
            q, factors = self._proposal(coords[s_idx], coords[c_idx], rng)
            new_lp = np.asarray(model.log_prob_fn(q.reshape(-1, d)), dtype=np.float64).reshape(nb, h)
            if np.any(np.isnan(new_lp)):
                raise ValueError("Probability function returned NaN")
            lnpdiff = factors + new_lp - log_prob[s_idx]
            acc = lnpdiff > np.log(rng.rand(nb, h))
            rows = s_idx[acc]
            coords[rows] = q[acc]
            log_prob[rows] = new_lp[acc]
            accepted[rows] = True
        return emcee.State(coords, log_prob=log_prob, blobs=None, random_state=state.random_state), accepted


class _BlockStretchMove(_BlockMove):
    """Goodman–Weare stretch move (emcee's :class:`~emcee.moves.StretchMove`, a = 2) per block."""

    def __init__(self, n_blocks: int, a: float = 2.0):
        super().__init__(n_blocks)
        self.a = float(a)

    def _proposal(self, s, c, rng):
        nb, h, d = s.shape
        zz = ((self.a - 1.0) * rng.rand(nb, h) + 1.0) ** 2 / self.a
        cp = np.take_along_axis(c, rng.randint(h, size=(nb, h))[..., None], axis=1)
        return cp - (cp - s) * zz[..., None], (d - 1.0) * np.log(zz)


class _BlockDEMove(_BlockMove):
    """Differential-evolution move (emcee's :class:`~emcee.moves.DEMove`) per block.

    ``q = x + γ (x_j − x_k) + ε``, ``j ≠ k`` from the complementary half,
    ``γ = 2.38/√(2d)`` (ter Braak 2006; Nelson et al. 2013), ``ε ~ N(0, 10⁻⁵)``; symmetric.
    """

    def _proposal(self, s, c, rng):
        nb, h, d = s.shape
        j = rng.randint(h, size=(nb, h))
        k = (j + 1 + rng.randint(h - 1, size=(nb, h))) % h
        cj = np.take_along_axis(c, j[..., None], axis=1)
        ck = np.take_along_axis(c, k[..., None], axis=1)
        gamma = 2.38 / np.sqrt(2.0 * d)
        q = s + gamma * (cj - ck) + 1e-5 * rng.randn(nb, h, d)
        return q, np.zeros((nb, h))


def block_moves(nb: int, move: str):
    if move == "stretch":
        return [_BlockStretchMove(nb)]
    if move == "de":
        return [(_BlockDEMove(nb), 0.8), (_BlockStretchMove(nb), 0.2)]
    raise ValueError(f"move must be 'stretch' or 'de'; got {move!r}")
