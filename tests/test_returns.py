"""Returns-to-go and soft returns-to-go against hand-computed values, including every end-of-episode rule."""
import numpy as np

from offrl_jax.data.returns import returns_to_go, soft_returns_to_go, soft_returns_to_go_from_states

A = np.testing.assert_allclose

R = np.array([1.0, 2.0, 3.0, 4.0, 5.0], np.float32)
TERM = np.array([0, 1, 0, 0, 0], np.float32)  # episode 1 = rows 0-1, ends in a terminal
TIMEOUT = np.array([0, 0, 0, 1, 0], np.float32)  # episode 2 = rows 2-3, ends in a time-out; row 4 = dataset end


def test_returns_to_go_with_timeout_tail():
    # gamma 0.5.  terminal: [1 + .5*2, 2] = [2, 2]; time-out tail 4/(1-.5) = 8 -> [3 + .5*8, 8] = [7, 8];
    # dataset end 5/(1-.5) = 10
    A(returns_to_go(R, TERM, TIMEOUT, 0.5), [2.0, 2.0, 7.0, 8.0, 10.0])


def test_returns_to_go_without_tail():
    A(returns_to_go(R, TERM, TIMEOUT, 0.5, timeout_tail=False), [2.0, 2.0, 5.0, 4.0, 5.0])


def test_terminal_wins_over_timeout_on_the_same_step():
    # both flags on row 1: it is a true terminal, no tail
    A(returns_to_go(R[:2], np.array([0, 1.0]), np.array([0, 1.0]), 0.5), [2.0, 2.0])


def test_every_visit_long_episode_matches_loop():
    rng = np.random.default_rng(0)
    r = rng.normal(size=3000).astype(np.float32)
    term = (rng.random(3000) < 0.01).astype(np.float32)
    timeouts = (rng.random(3000) < 0.01).astype(np.float32) * (1 - term)
    expected, g = np.zeros(3000), 0.0
    for t in reversed(range(3000)):
        end = term[t] or timeouts[t] or t == 2999
        tail = end and not term[t]
        g = r[t] / (1 - 0.99) if tail else r[t] + (0.0 if end else 0.99 * g)
        expected[t] = g
    A(returns_to_go(r, term, timeouts, 0.99), expected, rtol=2e-4, atol=2e-3)


def test_soft_returns_time_out_tail_covers_entropy():
    # gamma .5, alpha 1, H(s') = [2, 4]: r' = [1 + .5*2, 1 + .5*4] = [2, 3]; time-out tail 3/(1-.5) = 6; G0 = 2 + .5*6
    r, h = np.array([1.0, 1.0], np.float32), np.array([2.0, 4.0], np.float32)
    A(soft_returns_to_go(r, h, np.zeros(2), np.array([0, 1.0]), 0.5, 1.0), [5.0, 6.0])


def test_soft_returns_terminal_has_no_entropy_bonus():
    # terminal at row 1: r'_1 = 1 (absorbing successor), G0 = (1 + .5*2) + .5*1 = 2.5
    r, h = np.array([1.0, 1.0], np.float32), np.array([2.0, 4.0], np.float32)
    A(soft_returns_to_go(r, h, np.array([0, 1.0]), np.zeros(2), 0.5, 1.0), [2.5, 1.0])


def test_soft_returns_alpha_scales_bonus_and_zero_alpha_is_hard():
    r, h = np.array([1.0, 1.0], np.float32), np.array([2.0, 4.0], np.float32)
    A(soft_returns_to_go(r, h, np.array([0, 1.0]), np.zeros(2), 0.5, 0.0), returns_to_go(r, np.array([0, 1.0]),
                                                                                       np.zeros(2), 0.5))
    # alpha 2: r'_0 = 1 + .5*2*2 = 3, G0 = 3 + .5*1 = 3.5
    A(soft_returns_to_go(r, h, np.array([0, 1.0]), np.zeros(2), 0.5, 2.0), [3.5, 1.0])


def test_soft_returns_dataset_end_gets_the_tail_and_timeout_tail_false_gives_none():
    # no flags: row 1 is the dataset end, treated as a time-out: r' = [2, 3], tail 3 / (1 - .5) = 6, G0 = 2 + .5 * 6
    r, h = np.array([1.0, 1.0], np.float32), np.array([2.0, 4.0], np.float32)
    A(soft_returns_to_go(r, h, np.zeros(2), np.zeros(2), 0.5, 1.0), [5.0, 6.0])
    # the authors' stored code's convention: no tail, G0 = 2 + .5 * 3
    A(soft_returns_to_go(r, h, np.zeros(2), np.zeros(2), 0.5, 1.0, timeout_tail=False), [3.5, 3.0])


def test_soft_returns_from_states_authors_end_of_episode():
    # gamma .5, alpha 1; entropies at each row's own state.  Episode 1 (rows 0-1) ends in a time-out: r_1 -> 2/.5 = 4,
    # H_1 -> 8/.5 = 16; the last row has no entropy term: G1 = 4, G0 = 1 + .5*4 + .5*16 = 11.  Episode 2 (rows 2-3)
    # ends in a terminal, no tail: G3 = 2, G2 = 1 + .5*2 + .5*8 = 6 (episode 1 does not see H_2 = 4)
    r, h = np.array([1.0, 2.0, 1.0, 2.0], np.float32), np.array([4.0, 8.0, 4.0, 8.0], np.float32)
    term, timeout = np.array([0, 0, 0, 1.0]), np.array([0, 1.0, 0, 0])
    A(soft_returns_to_go_from_states(r, h, term, timeout, 0.5, 1.0), [11.0, 4.0, 6.0, 2.0])
    A(soft_returns_to_go_from_states(r, h, term, timeout, 0.5, 2.0), [19.0, 4.0, 10.0, 2.0])  # alpha 2: 1 + 2 + 16
    # the dataset end is a time-out; without the tail G1 = 2, G0 = 1 + .5*2 + .5*8
    A(soft_returns_to_go_from_states(r[:2], h[:2], np.zeros(2), np.zeros(2), 0.5, 1.0), [11.0, 4.0])
    A(soft_returns_to_go_from_states(r[:2], h[:2], np.zeros(2), np.zeros(2), 0.5, 1.0, timeout_tail=False), [6.0, 2.0])


def test_soft_returns_from_states_match_the_sum_over_each_episode():
    # G_t = R_t + alpha sum_{k=t+1}^{T} gamma^(k-t) H'_k, T the episode's last row, written as the sum it is
    rng = np.random.default_rng(1)
    n, gamma, alpha = 400, 0.9, 0.3
    r, h = rng.normal(size=n).astype(np.float32), rng.normal(size=n).astype(np.float32)
    term = (rng.random(n) < 0.03).astype(np.float32)
    timeouts = (rng.random(n) < 0.03).astype(np.float32) * (1 - term)
    ends = [t for t in range(n) if term[t] or timeouts[t] or t == n - 1]
    expected, start = np.zeros(n), 0
    for end in ends:
        tail = 1 / (1 - gamma) if not term[end] else 1.0
        rr, hh = r[start:end + 1].astype(float), h[start:end + 1].astype(float)
        rr[-1], hh[-1] = rr[-1] * tail, hh[-1] * tail
        for t in range(len(rr)):
            expected[start + t] = sum(gamma ** (k - t) * rr[k] for k in range(t, len(rr))) + alpha * sum(
                gamma ** (k - t) * hh[k] for k in range(t + 1, len(hh)))
        start = end + 1
    A(soft_returns_to_go_from_states(r, h, term, timeouts, gamma, alpha), expected, rtol=1e-4, atol=1e-3)
