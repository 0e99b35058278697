"""The five-state corridor: a toy small enough to solve exactly, for watching the clip of eq. 7 at work.

::

    trap ← start ─ s1 ─ s2 ─ s3 ─ s4 → goal

Five states, ``start`` = 0 and s1…s4 = 1…4, and two actions, left and right. Moving left from ``start`` falls
into the trap and moving right from s4 reaches the goal; both end the episode. Every other move goes one state
left or right. Entering the goal pays ``GOAL_REWARD`` = +1, falling into the trap pays ``TRAP_REWARD`` = −1 and
every other step pays 0, with discount γ = 0.97. The best policy walks right five times and earns γ⁴ ≈ 0.885
from ``start``; the uniform policy earns about −0.65.

The policy is tabular: one logit per state and action, π_θ(a|s) = softmax(θ_s)_a. Because the corridor is tiny,
nothing is estimated. Each round V^π, Q^π, A^π and the discounted state visitation d^π are solved exactly from
small tridiagonal linear systems, and the surrogates of the paper become exact sums over states and actions,
weighted by the snapshot's visitation d^π_old(s) and its action probabilities π_old(a|s):

    L^CPI(θ)    = Σ_s d_old(s) Σ_a π_old(a|s) r(s,a) Â(s,a)                            (eq. 6)
    L^CLIP(θ)   = Σ_s d_old(s) Σ_a π_old(a|s) min(r Â, clip(r, 1−ε, 1+ε) Â)             (eq. 7)
    L^KLPEN(θ)  = L^CPI(θ) − β Σ_s d_old(s) KL[π_old(·|s), π_θ(·|s)]                    (eq. 8)

with the ratio r(s,a) = π_θ(a|s) / π_old(a|s). d^π is the unnormalised discounted visitation
d^π(s) = Σ_t γ^t P(s_t = s | s_0 = start), the weighting under which the gradient of L^CPI at θ = θ_old is
exactly the policy gradient ∇_θ V^π(start) (the policy gradient theorem).

``Explorer`` plays Algorithm 1 on it: a round freezes the snapshot θ_old, solves the advantages once (plus,
optionally, seeded Gaussian noise that stands in for the error of estimating them from samples), then takes K
plain gradient-ascent steps on the chosen surrogate (one tick = one epoch; the "minibatch" is the whole, exact
batch) before θ_old ← θ. ``run(settings)`` plays it and returns the trace.

Everything is plain Python floats, step for step as in the book's in-browser explorer
(``book/_static/explorer/corridor-math.js``). Even e^x, log x and cos x are computed here from + − × ÷ alone
(``exp``, ``log``, ``cos_turns`` at the end of the module), because a browser's ``Math.exp`` and the C library's
``exp`` may differ in the last bit and a long run with a huge step amplifies such a bit. IEEE arithmetic is the
same everywhere, so the two implementations give the same trajectory bit for bit: a test runs both.
"""

from __future__ import annotations

import math

from minippo.errors import MinippoError
from minippo.losses import adaptive_beta  # eq. 8's rule for β, in plain float arithmetic

N_STATES = 5
N_ACTIONS = 2
LEFT, RIGHT = 0, 1
STATE_NAMES = ("start", "s1", "s2", "s3", "s4")
ACTION_NAMES = ("left", "right")
GAMMA = 0.97
GOAL_REWARD = 1.0
TRAP_REWARD = -1.0
OBJECTIVES = ("clip", "cpi", "klpen")
# after every step each logit is kept within ±LOGIT_BOUND, so that π(a|s) ≥ e^−50 never underflows to zero
# (the presets stay far inside it; only extreme step sizes reach it)
LOGIT_BOUND = 25.0

# the explorer's starting settings; each preset below changes some of them
DEFAULTS = {
    "objective": "clip",  # clip (eq. 7) | cpi (eq. 6: no clip, no penalty) | klpen (eq. 8)
    "epsilon": 0.2,  # ε, the clip range
    "step_size": 0.3,  # α of the gradient-ascent step θ ← θ + α ∇_θ L
    "epochs": 10,  # K, gradient steps on one snapshot
    "noise": 0.2,  # standard deviation of the Gaussian noise added to each Â(s, a)
    "seed": 1,  # seeds the noise
    "kl_beta": 1.0,  # β's starting value (klpen)
    "kl_target": 0.01,  # d_targ of eq. 8's adaptive β (klpen)
    "gamma": GAMMA,
}
# the same noise and seed in all three, so that they differ only in what their titles say
PRESETS = {
    "clip": {"objective": "clip", "epsilon": 0.2, "epochs": 10, "step_size": 0.3, "noise": 0.2, "seed": 1},
    "noclip": {"objective": "cpi", "epsilon": 0.2, "epochs": 40, "step_size": 0.3, "noise": 0.2, "seed": 1},
    "hugestep": {"objective": "clip", "epsilon": 0.2, "epochs": 40, "step_size": 3.0, "noise": 0.2, "seed": 1},
}
PRESET_TITLES = {
    "clip": "Clipped objective",
    "noclip": "No clip, many epochs",
    "hugestep": "Clip, huge step, 40 epochs",
}
LIMITS = {"epsilon": (0.05, 0.5), "step_size": (0.001, 100.0), "epochs": (1, 100), "noise": (0.0, 1.0)}


# ---------------------------------------------------------------- the policy


def softmax_policy(logits):
    """π_θ(a|s) = exp θ_{s,a} / Σ_b exp θ_{s,b}, one row per state (shifted by the row's max for safety)."""
    probs = []
    for row in logits:
        top = max(row)
        exps = [exp(z - top) for z in row]
        total = sum(exps)
        probs.append([e / total for e in exps])
    return probs


# ---------------------------------------------------------------- exact values


def solve_tridiagonal(lower, diag, upper, rhs):
    """Solves the system lower[i] x[i−1] + diag[i] x[i] + upper[i] x[i+1] = rhs[i] (Thomas algorithm).

    The corridor's systems are I − γP with γ < 1, strictly diagonally dominant, so no pivoting is needed.
    """
    n = len(diag)
    c = [0.0] * n
    y = [0.0] * n
    c[0] = upper[0] / diag[0]
    y[0] = rhs[0] / diag[0]
    for i in range(1, n):
        denom = diag[i] - lower[i] * c[i - 1]
        c[i] = upper[i] / denom if i < n - 1 else 0.0
        y[i] = (rhs[i] - lower[i] * y[i - 1]) / denom
    x = [0.0] * n
    x[n - 1] = y[n - 1]
    for i in range(n - 2, -1, -1):
        x[i] = y[i] - c[i] * x[i + 1]
    return x


def state_values(probs, gamma=GAMMA):
    """V^π, from the Bellman equation V(s) = Σ_a π(a|s) [R(s,a) + γ V(s')] written as (I − γ P^π) V = R^π."""
    lower = [0.0] * N_STATES
    upper = [0.0] * N_STATES
    rhs = [0.0] * N_STATES
    for s in range(N_STATES):
        if s > 0:
            lower[s] = -gamma * probs[s][LEFT]
        else:
            rhs[s] += probs[s][LEFT] * TRAP_REWARD
        if s < N_STATES - 1:
            upper[s] = -gamma * probs[s][RIGHT]
        else:
            rhs[s] += probs[s][RIGHT] * GOAL_REWARD
    return solve_tridiagonal(lower, [1.0] * N_STATES, upper, rhs)


def action_values(values, gamma=GAMMA):
    """Q^π(s,a) = R(s,a) + γ V^π(s'), with V = 0 past the trap and the goal (the episode has ended)."""
    q = []
    for s in range(N_STATES):
        left = TRAP_REWARD if s == 0 else gamma * values[s - 1]
        right = GOAL_REWARD if s == N_STATES - 1 else gamma * values[s + 1]
        q.append([left, right])
    return q


def advantages_of(probs, q, values):
    """A^π(s,a) = Q^π(s,a) − V^π(s)."""
    return [[q[s][a] - values[s] for a in range(N_ACTIONS)] for s in range(N_STATES)]


def visitation(probs, gamma=GAMMA):
    """d^π(s) = Σ_t γ^t P(s_t = s), from d = e_start + γ (P^π)ᵀ d (unnormalised: it sums to the expected
    discounted episode length, not to 1)."""
    lower = [0.0] * N_STATES
    upper = [0.0] * N_STATES
    rhs = [0.0] * N_STATES
    rhs[0] = 1.0
    for s in range(N_STATES):
        if s > 0:
            lower[s] = -gamma * probs[s - 1][RIGHT]  # arrivals from the left neighbour moving right
        if s < N_STATES - 1:
            upper[s] = -gamma * probs[s + 1][LEFT]  # arrivals from the right neighbour moving left
    return solve_tridiagonal(lower, [1.0] * N_STATES, upper, rhs)


def expected_return(logits, gamma=GAMMA):
    """J(θ) = V^π_θ(start), the expected discounted return of an episode."""
    return state_values(softmax_policy(logits), gamma)[0]


def optimal_return(gamma=GAMMA):
    """Walking right five times: the goal's reward arrives on the fifth step, discounted by γ⁴."""
    discount = 1.0
    for _ in range(N_STATES - 1):
        discount *= gamma
    return GOAL_REWARD * discount


# ---------------------------------------------------------------- the snapshot and the surrogates


class Snapshot:
    """What Algorithm 1 freezes at the start of a round: θ_old, π_old, d^π_old and the advantages Â.

    ``noise`` is a list of N_STATES × N_ACTIONS standard-normal draws; Â = A^π_old + noise_scale × noise.
    """

    def __init__(self, logits, gamma=GAMMA, noise=None, noise_scale=0.0):
        self.logits = [list(row) for row in logits]
        self.probs = softmax_policy(self.logits)
        self.values = state_values(self.probs, gamma)
        self.q = action_values(self.values, gamma)
        self.exact_advantages = advantages_of(self.probs, self.q, self.values)
        self.visitation = visitation(self.probs, gamma)
        self.advantages = [list(row) for row in self.exact_advantages]
        if noise is not None:
            for s in range(N_STATES):
                for a in range(N_ACTIONS):
                    self.advantages[s][a] += noise_scale * noise[s * N_ACTIONS + a]
        self.visitation_total = sum(self.visitation)


def ratios(probs, snapshot):
    """r(s,a) = π_θ(a|s) / π_old(a|s)."""
    return [[probs[s][a] / snapshot.probs[s][a] for a in range(N_ACTIONS)] for s in range(N_STATES)]


def kl_per_state(snapshot, probs):
    """KL[π_old(·|s), π_θ(·|s)] = Σ_a π_old(a|s) log(π_old(a|s) / π_θ(a|s)), eq. 8's order."""
    return [
        sum(snapshot.probs[s][a] * log(snapshot.probs[s][a] / probs[s][a]) for a in range(N_ACTIONS))
        for s in range(N_STATES)
    ]


def mean_kl(snapshot, probs):
    """Ê_t[KL[π_old(·|s_t), π_θ(·|s_t)]]: the per-state KL averaged over the snapshot's normalised visitation,
    which is what a sampled batch would measure."""
    kls = kl_per_state(snapshot, probs)
    return sum(snapshot.visitation[s] * kls[s] for s in range(N_STATES)) / snapshot.visitation_total


def _logit_gradient(probs, grad_logp_row, s):
    """Carries ∂L/∂ log π(a|s) to the logits with ∂ log π(a|s)/∂θ_{s,j} = 1[j = a] − π(j|s)."""
    total = sum(grad_logp_row)
    return [grad_logp_row[j] - probs[s][j] * total for j in range(N_ACTIONS)]


def _surrogate(logits, snapshot, term):
    """Σ_(s,a) w f(r, Â) and its gradient with respect to the logits, w = d_old(s) π_old(a|s), for a per-sample
    ``term(w, r, Â)`` = (w f, w r ∂f/∂r), the value and ∂L/∂ log π_θ(a|s) (∂r/∂ log π_θ = r)."""
    probs = softmax_policy(logits)
    value = 0.0
    grad = []
    for s in range(N_STATES):
        row = []
        for a in range(N_ACTIONS):
            weight = snapshot.visitation[s] * snapshot.probs[s][a]
            ratio = probs[s][a] / snapshot.probs[s][a]
            weighted, slope = term(weight, ratio, snapshot.advantages[s][a])
            value += weighted
            row.append(slope)
        grad.append(_logit_gradient(probs, row, s))
    return value, grad


def cpi_objective(logits, snapshot):
    """L^CPI (eq. 6) and its gradient with respect to the logits: f = r Â, so
    ∂L/∂ log π_θ(a|s) = d_old(s) π_old(a|s) r(s,a) Â(s,a) = d_old(s) π_θ(a|s) Â(s,a).
    """
    return _surrogate(logits, snapshot, lambda weight, ratio, advantage: (weight * ratio * advantage,) * 2)


def clip_objective(logits, snapshot, epsilon):
    """L^CLIP (eq. 7) and its gradient with respect to the logits.

    The clipped term is flat in θ, so ∂L/∂ log π_θ(a|s) = d_old(s) π_old(a|s) r Â where r Â ≤ clip(r) Â (the
    unclipped term is the min) and 0 where the clipped term wins: r > 1+ε with Â > 0, or r < 1−ε with Â < 0.
    """

    def term(weight, ratio, advantage):
        unclipped = ratio * advantage
        clipped = min(max(ratio, 1.0 - epsilon), 1.0 + epsilon) * advantage
        return (weight * unclipped,) * 2 if unclipped <= clipped else (weight * clipped, 0.0)

    return _surrogate(logits, snapshot, term)


def kl_penalty_objective(logits, snapshot, beta):
    """L^KLPEN (eq. 8's surrogate) and its gradient: L^CPI − β Σ_s d_old(s) KL[π_old(·|s), π_θ(·|s)].

    ∂KL_s/∂θ_{s,j} = π_θ(j|s) − π_old(j|s).
    """
    value, grad = cpi_objective(logits, snapshot)
    probs = softmax_policy(logits)
    kls = kl_per_state(snapshot, probs)
    for s in range(N_STATES):
        value -= beta * snapshot.visitation[s] * kls[s]
        for j in range(N_ACTIONS):
            grad[s][j] -= beta * snapshot.visitation[s] * (probs[s][j] - snapshot.probs[s][j])
    return value, grad


def clipped_mask(probs, snapshot, epsilon):
    """True where eq. 7's clipped term wins, i.e. where that (s, a) passes no gradient."""
    mask = []
    for s in range(N_STATES):
        row = []
        for a in range(N_ACTIONS):
            ratio = probs[s][a] / snapshot.probs[s][a]
            advantage = snapshot.advantages[s][a]
            row.append(ratio * advantage > min(max(ratio, 1.0 - epsilon), 1.0 + epsilon) * advantage)
        mask.append(row)
    return mask


def clip_fraction(probs, snapshot, epsilon):
    """The snapshot-weighted share of (s, a) whose ratio has left the band [1−ε, 1+ε] (like losses.clip_fraction)."""
    total = 0.0
    for s in range(N_STATES):
        for a in range(N_ACTIONS):
            if abs(probs[s][a] / snapshot.probs[s][a] - 1.0) > epsilon:
                total += snapshot.visitation[s] * snapshot.probs[s][a]
    return total / snapshot.visitation_total


def kl_limit(epsilon):
    """The KL past which the explorer's trust-region light reads "broken": ε².

    To second order KL[π_old, π] ≈ ½ Σ_a π_old(a) (r_a − 1)², so a policy whose every ratio sits on the edge of
    the band [1−ε, 1+ε] is about ε²/2 away from its snapshot. The clip stops a ratio near that edge, not on it
    (the step that crosses the edge overshoots, and in a state where one action is already likely only the other
    action's ratio can reach the band), so the light allows twice that: a KL beyond ε² means the policy has left
    the region the band describes.
    """
    return epsilon * epsilon


# ---------------------------------------------------------------- seeded noise, portable to JavaScript


class Noise:
    """Standard-normal draws from the mulberry32 generator and the Box–Muller transform.

    mulberry32 is a 32-bit integer generator: the same seed gives the same uniforms, bit for bit, here and in
    JavaScript (``Math.imul``, ``>>>``), so the explorer in the browser draws the same noise as this module.
    """

    def __init__(self, seed):
        self.state = int(seed) & 0xFFFFFFFF

    def uniform(self):
        """A float in [0, 1) with 32 random bits."""
        self.state = (self.state + 0x6D2B79F5) & 0xFFFFFFFF
        t = self.state
        t = _imul(t ^ (t >> 15), t | 1)
        t ^= (t + _imul(t ^ (t >> 7), t | 61)) & 0xFFFFFFFF
        return ((t ^ (t >> 14)) & 0xFFFFFFFF) / 4294967296.0

    def normal(self):
        """One standard-normal draw: √(−2 log u₁) cos(2π u₂), with u₁ in (0, 1]."""
        u1 = 1.0 - self.uniform()
        u2 = self.uniform()
        return math.sqrt(-2.0 * log(u1)) * cos_turns(u2)


def _imul(a, b):
    """JavaScript's Math.imul on unsigned 32-bit values: the low 32 bits of the product."""
    return (a * b) & 0xFFFFFFFF


# ---------------------------------------------------------------- Algorithm 1 on the corridor


def check_settings(settings):
    """Merges ``settings`` into DEFAULTS and checks every value; raises MinippoError with a one-line message."""
    unknown = set(settings) - set(DEFAULTS)
    if unknown:
        raise MinippoError(f"unknown corridor setting(s): {', '.join(sorted(unknown))}; known: {', '.join(DEFAULTS)}")
    merged = dict(DEFAULTS)
    merged.update(settings)
    if merged["objective"] not in OBJECTIVES:
        raise MinippoError(f"objective must be one of {', '.join(OBJECTIVES)}, not {merged['objective']!r}")
    for key, (low, high) in LIMITS.items():
        value = merged[key]
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not low <= value <= high:
            raise MinippoError(f"{key} must be a number in [{low}, {high}], not {value!r}")
    if merged["epochs"] != int(merged["epochs"]):
        raise MinippoError(f"epochs must be a whole number, not {merged['epochs']!r}")
    merged["epochs"] = int(merged["epochs"])
    seed = merged["seed"]
    if isinstance(seed, bool) or not isinstance(seed, int) or not 0 <= seed < 2**32:
        raise MinippoError(f"seed must be a whole number in [0, 2**32), not {seed!r}")
    for key in ("gamma", "kl_beta", "kl_target"):
        if isinstance(merged[key], bool) or not isinstance(merged[key], (int, float)):
            raise MinippoError(f"{key} must be a number, not {merged[key]!r}")
    if not 0.0 < merged["gamma"] < 1.0:
        raise MinippoError(f"gamma must be in (0, 1), not {merged['gamma']!r}")
    if not merged["kl_beta"] > 0.0 or not merged["kl_target"] > 0.0:
        raise MinippoError("kl_beta and kl_target must be positive")
    return merged


class Explorer:
    """Algorithm 1 on the corridor, one tick at a time, exactly as the in-browser explorer plays it.

    The state starts at round 1, epoch 0: the snapshot of the uniform policy (θ = 0) is frozen and its
    advantages solved. Each ``tick`` takes one gradient step θ ← θ + α ∇_θ L on the frozen snapshot; the tick
    after the K-th starts a new round first (θ_old ← θ, advantages solved again, fresh noise).
    Settings may change between ticks with ``set``; a new objective, ε or step size acts on the next step,
    new noise on the next round's advantages.
    """

    def __init__(self, settings=None):
        self.settings = check_settings(settings or {})
        self.noise = Noise(self.settings["seed"])
        self.logits = [[0.0] * N_ACTIONS for _ in range(N_STATES)]
        self.beta = self.settings["kl_beta"]
        self.round = 0
        self.tick_count = 0
        self.optimal = optimal_return(self.settings["gamma"])
        self._begin_round()

    def set(self, key, value):
        settings = dict(self.settings)
        settings[key] = value
        self.settings = check_settings(settings)

    def _begin_round(self):
        # ten draws every round, whatever the noise scale, so changing the scale mid-run keeps the same stream
        draws = [self.noise.normal() for _ in range(N_STATES * N_ACTIONS)]
        self.snapshot = Snapshot(self.logits, self.settings["gamma"], draws, self.settings["noise"])
        self.round += 1
        self.epoch = 0

    def _end_round(self):
        """θ_old ← θ; under klpen, eq. 8 adapts β from this round's KL first."""
        if self.settings["objective"] == "klpen":
            self.beta = adaptive_beta(self.beta, self.kl(), self.settings["kl_target"])
        self._begin_round()

    def objective(self, logits=None):
        """The chosen surrogate and its gradient at ``logits`` (the current θ by default)."""
        logits = self.logits if logits is None else logits
        name = self.settings["objective"]
        if name == "clip":
            return clip_objective(logits, self.snapshot, self.settings["epsilon"])
        if name == "klpen":
            return kl_penalty_objective(logits, self.snapshot, self.beta)
        return cpi_objective(logits, self.snapshot)

    def tick(self):
        """One epoch: one gradient-ascent step on the surrogate of the frozen snapshot."""
        if self.epoch >= self.settings["epochs"]:
            self._end_round()
        _, grad = self.objective()
        step = self.settings["step_size"]
        self.logits = [
            [min(max(self.logits[s][a] + step * grad[s][a], -LOGIT_BOUND), LOGIT_BOUND) for a in range(N_ACTIONS)]
            for s in range(N_STATES)
        ]
        self.epoch += 1
        self.tick_count += 1
        return self.record()

    def probs(self):
        return softmax_policy(self.logits)

    def kl(self):
        return mean_kl(self.snapshot, self.probs())

    def record(self):
        """Everything the explorer shows after a tick."""
        probs = self.probs()
        epsilon = self.settings["epsilon"]
        kl = mean_kl(self.snapshot, probs)
        value, _ = self.objective()
        return {
            "tick": self.tick_count,
            "round": self.round,
            "epoch": self.epoch,
            "objective": self.settings["objective"],
            "logits": [list(row) for row in self.logits],
            "probs": probs,
            "ratios": ratios(probs, self.snapshot),
            "advantages": [list(row) for row in self.snapshot.advantages],
            # where the clip zeroes the gradient: only under the clipped objective
            "clipped": clipped_mask(probs, self.snapshot, epsilon)
            if self.settings["objective"] == "clip"
            else [[False] * N_ACTIONS for _ in range(N_STATES)],
            "clip_fraction": clip_fraction(probs, self.snapshot, epsilon),  # outside the band, any objective
            "surrogate": value,
            "return": state_values(probs, self.settings["gamma"])[0],
            "kl": kl,
            "kl_limit": kl_limit(epsilon),
            "held": kl <= kl_limit(epsilon),
            "beta": self.beta,
        }


def run(settings=None, ticks=200, changes=None):
    """Plays ``ticks`` ticks of the explorer and returns one ``Explorer.record`` per tick.

    ``settings`` may name a preset (``{"preset": "noclip", "noise": 0.1}``); ``changes`` maps a tick number to
    the settings changed just before that tick, e.g. ``{150: {"objective": "clip"}}``, as a reader does mid-run.
    """
    settings = dict(settings or {})
    preset = settings.pop("preset", None)
    if preset is not None:
        if preset not in PRESETS:
            raise MinippoError(f"preset must be one of {', '.join(PRESETS)}, not {preset!r}")
        settings = {**PRESETS[preset], **settings}
    explorer = Explorer(settings)
    changes = {int(k): v for k, v in (changes or {}).items()}
    trace = []
    for tick in range(1, ticks + 1):
        for key, value in changes.get(tick, {}).items():
            explorer.set(key, value)
        trace.append(explorer.tick())
    return trace


# ---------------------------------------------------------------- e^x, log x and cos x from + − × ÷ alone
# Each is a textbook range reduction and a short series; IEEE-754 rounds + − × ÷ (and √) the same way in every
# language, so these give the same bits in Python and in JavaScript. Accurate to about one unit in the last place.

LN2_HI = 6.93147180369123816490e-01  # ln 2 split in two: LN2_HI has zero low bits, so k × LN2_HI is exact
LN2_LO = 1.90821492927058770002e-10
INV_LN2 = 1.44269504088896338700e00
SQRT_HALF = 0.70710678118654752440
HALF_PI = 1.57079632679489661923


def exp(x):
    """e^x = 2^k e^r with k = round(x / ln 2) and |r| ≤ ½ ln 2, e^r by its Taylor series to r¹⁴/14!."""
    if x < -708.0:
        return 0.0
    k = math.floor(x * INV_LN2 + 0.5)
    r = (x - k * LN2_HI) - k * LN2_LO
    series = 1.0
    for n in range(14, 0, -1):
        series = 1.0 + series * r / n
    return math.ldexp(series, k)  # exact: a power of two (the JavaScript port multiplies by 2 or ½ k times)


def log(x):
    """log x = e ln 2 + log m with x = m 2^e, m in [√½, √2), and log m = 2 atanh(s), s = (m − 1)/(m + 1)."""
    m, e = math.frexp(x)
    if m < SQRT_HALF:
        m *= 2.0
        e -= 1
    s = (m - 1.0) / (m + 1.0)
    s2 = s * s
    series = 1.0 / 21.0
    for n in range(19, 0, -2):  # 2 atanh s = 2 (s + s³/3 + s⁵/5 + … + s²¹/21)
        series = 1.0 / n + s2 * series
    return e * LN2_HI + (e * LN2_LO + 2.0 * s * series)


def _cos_quarter(f):
    """cos(f π/2) for f in [0, 1], by its Taylor series to (f π/2)²⁴/24!."""
    a = f * HALF_PI
    a2 = a * a
    series = 1.0
    for k in range(12, 0, -1):
        series = 1.0 - a2 * series / ((2 * k - 1) * (2 * k))
    return series


def _sin_quarter(f):
    """sin(f π/2) for f in [0, 1], by its Taylor series to (f π/2)²⁵/25!."""
    a = f * HALF_PI
    a2 = a * a
    series = 1.0
    for k in range(12, 0, -1):
        series = 1.0 - a2 * series / ((2 * k) * (2 * k + 1))
    return a * series


def cos_turns(u):
    """cos(2π u) for u in [0, 1): the quarter turn q = ⌊4u⌋ picks ±cos or ±sin of the rest, f π/2."""
    quarter = u * 4.0
    q = math.floor(quarter)
    f = quarter - q
    if q == 0:
        return _cos_quarter(f)
    if q == 1:
        return -_sin_quarter(f)
    if q == 2:
        return -_cos_quarter(f)
    return _sin_quarter(f)
