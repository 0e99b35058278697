"""Chapter 14's distances to the exact optimum π* over more seeds and iterations than a page can run.

    python -m benchmarks.grpo_dpo grpo   # -> results/grpo_kl_placement.csv
    python -m benchmarks.grpo_dpo dpo    # -> results/dpo_pairs.csv

Both work in the chapter's enumerable setting (prompts of three words, responses of at most two tokens, β = 0.5), from
the pretrained model and reward model of ``pretrained_pieces(seed=0)``, the pieces of the book's draw 0.

``grpo`` separates the estimator of the KL from its place. GRPO's KL is in the loss as k3; ``kl_estimator="k2"``
keeps it in the loss, per token, with the estimator whose gradient there is the reverse KL's; ``kl_in="reward"``
moves the whole response's KL into the reward. Each of the three runs with GRPO's other defaults and with the std
division and the 1/|y| weights off, beside PPO, and KL[π_θ ‖ π*] is written after every iteration.

``dpo`` varies the number of preference pairs (each seed draws its pairs once and takes the first n, so a smaller
set is part of every larger one) and writes KL[π_θ ‖ π*] after every pass with the share of π*'s probability on the
responses that some pair holds. More pairs bring two things, more responses covered and more labels for each; one more
run per seed separates them: as many pairs as the largest set, drawn only among the responses that the first
``--restricted`` pairs cover (π_ref renormalised over them, on the prompts where they hold two or more), so that it
has the small set's coverage and the large set's number of labels.
"""

from __future__ import annotations

import os

for _name in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_name] = "1"  # before NumPy starts its thread pool

import argparse  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402

from benchmarks import common  # noqa: E402

BETA = 0.5
SHORT = dict(prompt_len=3, response_len=2)
GRPO_FIELDS = ["method", "setting", "kl", "seed", "iteration", "kl_to_optimum", "commit", "command"]
DPO_FIELDS = [
    "pairs", "drawn_among", "seed", "pass", "kl_to_optimum", "covered_optimum_mass", "accuracy", "commit", "command"
]
# (the name in the record, GRPOConfig's fields): where the KL sits and which estimator it uses
PLACEMENTS = {"k3 in the loss": {}, "k2 in the loss": dict(kl_estimator="k2"), "in the reward": dict(kl_in="reward")}
SETTINGS = {"GRPO's defaults": {}, "std and 1/|y| off": dict(normalize_std=False, average_over_tokens=False)}


def enumerable(seed: int = 0):
    """The pretrained pieces and the exact optimum of the short-response setting."""
    from minippo.lm.rlhf import (
        all_prompts,
        optimal_log_probs,
        pretrained_pieces,
        response_log_probs,
        short_response_scores,
    )

    reference, reward_model, _ = pretrained_pieces(seed=seed)
    prompts = all_prompts(3)
    logp_ref = response_log_probs(reference, prompts)
    scores = short_response_scores(reward_model, prompts)
    logp_star, _ = optimal_log_probs(logp_ref, scores, BETA)
    return reference, reward_model, prompts, logp_ref, scores, logp_star


def run_grpo(seeds, iterations: int, command: str) -> list[dict]:
    from minippo.lm.grpo import GRPOConfig, train_grpo
    from minippo.lm.rlhf import RLHFConfig, response_kl, response_log_probs, train_rlhf

    reference, reward_model, prompts, logp_ref, _, logp_star = enumerable()
    commit, rows = common.git_commit(), []
    runs = [("PPO", "", "in the reward", None)] + [
        ("GRPO", setting, kl, {**SETTINGS[setting], **PLACEMENTS[kl]}) for setting in SETTINGS for kl in PLACEMENTS
    ]
    for method, setting, kl, fields in runs:
        for seed in seeds:
            started = time.perf_counter()
            curve = [response_kl(logp_ref, logp_star)]

            def record(stats, policy, curve=curve):
                curve.append(response_kl(response_log_probs(policy, prompts), logp_star))

            if method == "PPO":
                train_rlhf(reference, reward_model, RLHFConfig(beta=BETA, updates=iterations, seed=seed, **SHORT),
                           record)
            else:
                config = GRPOConfig(beta=BETA, updates=iterations, seed=seed, **SHORT, **fields)
                train_grpo(reference, reward_model, config, record)
            rows += [dict(method=method, setting=setting, kl=kl, seed=seed, iteration=i, kl_to_optimum=f"{d:.6g}",
                          commit=commit, command=command) for i, d in enumerate(curve)]
            print(f"{method} {setting} {kl} seed {seed}: {curve[30]:.3f} at 30, {curve[-1]:.3f} at {iterations}"
                  f" ({time.perf_counter() - started:.0f} s)", flush=True)
    return rows


def draw_pairs(prompts, logp_ref, scores, n: int, rng, allowed=None):
    """n pairs of short responses: a prompt, two responses drawn from π_ref, the first preferred with the
    Bradley–Terry probability of the reward model's scores. Returns (prompt index, winner, loser), each (n,).
    ``allowed`` (prompts, responses), if given: only those responses, on the prompts with two or more of them."""
    if allowed is None:
        which = rng.integers(len(prompts), size=n)
        probs = np.exp(logp_ref[which])
    else:
        which = rng.choice(np.flatnonzero(allowed.sum(axis=1) >= 2), size=n)
        probs = np.exp(logp_ref[which]) * allowed[which]
    probs /= probs.sum(axis=1, keepdims=True)
    cumulative = probs.cumsum(axis=1)
    first = (rng.random((n, 1)) > cumulative).sum(axis=1).clip(max=probs.shape[1] - 1)
    second = (rng.random((n, 1)) > cumulative).sum(axis=1).clip(max=probs.shape[1] - 1)
    first_wins = rng.random(n) < 1 / (1 + np.exp(-(scores[which, first] - scores[which, second])))
    return which, np.where(first_wins, first, second), np.where(first_wins, second, first)


def run_dpo(seeds, sizes, passes: int, restricted: int, command: str) -> list[dict]:
    from minippo.lm import language as lm
    from minippo.lm.dpo import DPOConfig, train_dpo
    from minippo.lm.rlhf import response_kl, response_log_probs, short_responses

    reference, _, prompts, logp_ref, scores, logp_star = enumerable()
    tokens, lengths = short_responses()
    commit, rows = common.git_commit(), []
    start = response_kl(logp_ref, logp_star)

    def coverage(which, winner, loser):
        covered = np.zeros(logp_star.shape, dtype=bool)
        covered[which, winner] = covered[which, loser] = True
        return covered

    def train(seed, pairs, drawn_among):
        which, winner, loser = pairs

        def as_texts(responses):
            texts = np.full((len(which), 5), lm.TOKEN[lm.BOS])
            texts[:, :3], texts[:, 3:] = prompts[which], tokens[responses]
            return texts, 3 + lengths[responses]

        mass = float((np.exp(logp_star) * coverage(*pairs)).sum(axis=1).mean())
        started, curve = time.perf_counter(), []

        def record(stats, policy):
            curve.append((response_kl(response_log_probs(policy, prompts), logp_star), stats["accuracy"]))

        train_dpo(reference, as_texts(winner), as_texts(loser),
                  DPOConfig(beta=BETA, epochs=passes, prompt_len=3, seed=seed), record)
        common_fields = {"pairs": len(which), "drawn_among": drawn_among, "seed": seed,
                         "covered_optimum_mass": f"{mass:.6g}", "commit": commit, "command": command}
        rows.append({**common_fields, "pass": 0, "kl_to_optimum": f"{start:.6g}", "accuracy": ""})
        rows.extend({**common_fields, "pass": i, "kl_to_optimum": f"{d:.6g}", "accuracy": f"{a:.6g}"}
                    for i, (d, a) in enumerate(curve, start=1))
        print(f"DPO {len(which)} pairs among {drawn_among}, seed {seed}: covered {mass:.2f}, "
              + " ".join(f"{d:.3f}" for d, _ in curve) + f" ({time.perf_counter() - started:.0f} s)", flush=True)

    for seed in seeds:
        all_pairs = draw_pairs(prompts, logp_ref, scores, max(sizes), np.random.default_rng(seed + 5))
        for n in sizes:
            train(seed, tuple(part[:n] for part in all_pairs), "all responses")
        allowed = coverage(*(part[:restricted] for part in all_pairs))
        pairs = draw_pairs(prompts, logp_ref, scores, max(sizes), np.random.default_rng(seed + 6), allowed)
        train(seed, pairs, f"the first {restricted} pairs' responses")
    return rows


def seed_list(text: str) -> list[int]:
    first, _, last = text.partition("-")
    if not (first.isdigit() and (not last or last.isdigit())) or (last and int(last) < int(first)):
        raise argparse.ArgumentTypeError(f"seeds are N or N-M with N ≤ M, not {text!r}")
    return list(range(int(first), int(last or first) + 1))


def size_list(text: str) -> list[int]:
    try:
        sizes = [int(part) for part in text.split(",")]
    except ValueError:
        sizes = []
    if not sizes or min(sizes) < 1:
        raise argparse.ArgumentTypeError(f"pairs are whole numbers ≥ 1, separated by commas, not {text!r}")
    return sizes


@common.one_line_errors
def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.grpo_dpo", description=__doc__.split("\n\n")[0])
    parser.add_argument("which", choices=("grpo", "dpo"))
    parser.add_argument("--seeds", type=seed_list, default=seed_list("0-7"), help="N or N-M (default 0-7)")
    parser.add_argument("--iterations", type=int, default=120, help="GRPO's and PPO's iterations (default 120)")
    parser.add_argument("--pairs", type=size_list, default=size_list("500,2000,8000,16000"),
                        help="DPO's numbers of pairs, comma-separated (default 500,2000,8000,16000)")
    parser.add_argument("--passes", type=int, default=8, help="DPO's passes over the pairs (default 8)")
    parser.add_argument("--restricted", type=int, default=2000,
                        help="DPO's last run per seed: the most pairs, among the responses these first pairs cover")
    parser.add_argument("--out", default=None, help="the CSV to write (default: the record in benchmarks/results/)")
    args = parser.parse_args(argv)
    if args.iterations < 30 or args.passes < 1:
        raise common.BenchmarkError("--iterations must be at least 30 and --passes at least 1")
    if not 1 <= args.restricted <= max(args.pairs):
        raise common.BenchmarkError("--restricted must be between 1 and the largest number of --pairs")
    command = common.invocation("grpo_dpo", argv)
    if args.which == "grpo":
        rows, fields = run_grpo(args.seeds, args.iterations, command), GRPO_FIELDS
        out = args.out or common.RESULTS / "grpo_kl_placement.csv"
    else:
        rows, fields = run_dpo(args.seeds, args.pairs, args.passes, args.restricted, command), DPO_FIELDS
        out = args.out or common.RESULTS / "dpo_pairs.csv"
    common.write_rows(out, rows, fields)
    print(f"wrote {common.relative(out)}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
