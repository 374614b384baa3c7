"""The chain solver against dense linear algebra."""

import numpy as np

from gtrig.fusion.blocktri import solve_chain


def _random_system(N: int, d: int, p: int, rng: np.random.Generator):
    n = N * d + p
    J = np.zeros((3 * n, n))
    row = 0
    for i in range(N - 1):  # pairwise factors, with parameter columns
        for _ in range(d + 1):
            J[row, i * d:(i + 2) * d] = rng.normal(size=2 * d)
            J[row, N * d:] = rng.normal(size=p) * 0.3
            row += 1
    for i in range(N):
        J[row:row + d, i * d:(i + 1) * d] = rng.normal(size=(d, d))
        row += d
    J[row:row + p, N * d:] = np.eye(p)
    H = J.T @ J
    g = rng.normal(size=n)
    return H, g


def test_solution_and_marginals_match_dense() -> None:
    rng = np.random.default_rng(0)
    for d, p in ((3, 3), (6, 0)):
        N = 40
        H, g = _random_system(N, d, p, rng)
        Ad = np.stack([H[i * d:(i + 1) * d, i * d:(i + 1) * d] for i in range(N)])
        Ao = np.stack([H[i * d:(i + 1) * d, (i + 1) * d:(i + 2) * d] for i in range(N - 1)])
        Bb = np.stack([H[i * d:(i + 1) * d, N * d:] for i in range(N)])
        C = H[N * d:, N * d:]
        dx, dk, cov, cov_k = solve_chain(Ad, Ao, Bb, C, g[:N * d].reshape(N, d), g[N * d:], marginals=True)
        ref = np.linalg.solve(H, g)
        Hi = np.linalg.inv(H)
        np.testing.assert_allclose(dx.ravel(), ref[:N * d], rtol=1e-8, atol=1e-10)
        np.testing.assert_allclose(dk, ref[N * d:], rtol=1e-8, atol=1e-10)
        for i in (0, N // 2, N - 1):
            np.testing.assert_allclose(cov[i], Hi[i * d:(i + 1) * d, i * d:(i + 1) * d], rtol=1e-7, atol=1e-12)
        np.testing.assert_allclose(cov_k, Hi[N * d:, N * d:], rtol=1e-7, atol=1e-12)
