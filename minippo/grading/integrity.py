"""What a submission's own text and its worker say it used: the reference, the tests or the grader, or minippo's own
version of the chapter's exercise. A submission may use the library's version (it runs), but the grade says so: these
notes go to the integrity column of ``minippo grade``.

``scan_source`` reads a module's text here, in the grader, where the student's code cannot change the reading;
``answer_note`` words what the worker (minippo/grading/worker.py) saw the code call.
"""

from __future__ import annotations

import ast
from pathlib import Path

# the minippo functions and classes that are themselves the answer to a chapter's exercises: a submission may use
# them (it runs), but the grade says so
LIBRARY_ANSWERS = {
    "ch01_network": {"minippo.network": ["linear_backward", "tanh_backward", "MLP"], "minippo.optimizer": ["Adam"]},
    "ch02_distributions": {"minippo.distributions": ["Categorical", "DiagGaussian"]},
    "ch03_vanilla_pg": {"minippo.losses": ["pg_objective"]},
    "ch04_cpi": {"minippo.losses": ["cpi_objective"]},
    "ch05_clipping": {"minippo.losses": ["clip_objective", "clip_fraction"]},
    "ch06_the_min": {"minippo.losses": ["clip_objective"]},
    "ch07_advantages": {"minippo.advantages": ["discounted_returns", "td_residuals", "gae"]},
    "ch08_shared_network": {"minippo.losses": ["value_loss"]},
    "ch09_kl_penalty": {"minippo.losses": ["kl_penalty_objective", "adaptive_beta"],
                        "minippo.distributions": ["Categorical"]},
    "ch10_ppo_update": {"minippo.ppo": ["loss_and_grad", "update_minibatch", "Trainer", "train"],
                        "minippo.rollout": ["Rollout"]},
    "ch12_pixels": {"minippo.conv": ["conv2d_forward", "conv2d_backward"]},
    "ch13_language_model": {"minippo.lm.reward_model": ["bradley_terry_loss", "RewardModel"],
                            "minippo.lm.rlhf": ["kl_shaped_rewards", "train_rlhf"]},
    "ch14_grpo_dpo": {"minippo.lm.grpo": ["group_advantages", "grpo_objective", "k3", "kl_estimate_and_grad"],
                      "minippo.lm.dpo": ["dpo_loss", "dpo_loss_and_grad"]},
}  # fmt: skip
# what no submission needs: the reference, the tests, the grader
FORBIDDEN_IMPORTS = ("solutions", "_harness", "pytest", "_pytest", "minippo.grading", "tests")


def all_answers() -> dict[str, list[str]]:
    """Every chapter's answers together, {module: [names]}: what the worker reports a call to."""
    merged: dict[str, set] = {}
    for modules in LIBRARY_ANSWERS.values():
        for module, names in modules.items():
            merged.setdefault(module, set()).update(names)
    return {module: sorted(names) for module, names in merged.items()}


def answer_note(note: str, chapter: str) -> str | None:
    """A worker's note as the chapter's integrity note: "calls minippo.x.f" only when f answers this chapter's
    exercise (a later chapter may use an earlier one's from the library); other notes as they are."""
    if not note.startswith("calls "):
        return note
    module, _, name = note[len("calls ") :].rpartition(".")
    if name in LIBRARY_ANSWERS.get(chapter, {}).get(module, []):
        return f"calls {module}.{name}, minippo's own version of the exercise"
    return None


def scan_source(path: Path, chapter: str) -> list[str]:
    """The integrity notes for one module: imports of the reference, the tests or the grader, and uses of minippo's
    own version of the chapter's exercises. Empty when the text holds none of them."""
    try:
        tree = ast.parse(path.read_text(encoding="utf-8", errors="replace"))
    except (OSError, SyntaxError, ValueError):
        return []
    answers = LIBRARY_ANSWERS.get(chapter, {})
    notes, modules, names = [], set(), set()
    for node in ast.walk(tree):
        imported = []
        if isinstance(node, ast.Import):
            imported = [(alias.name, None) for alias in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module and not node.level:
            imported = [(node.module, alias.name) for alias in node.names]
        for module, name in imported:
            full = f"{module}.{name}" if name else module
            if any(full == f or full.startswith(f + ".") or module == f for f in FORBIDDEN_IMPORTS):
                notes.append(f"imports {full}")
            if name and module in answers and name in answers[module]:
                notes.append(f"uses {module}.{name}, minippo's own version of the exercise")
            if name and f"{module}.{name}" in answers:
                modules.add(f"{module}.{name}")
            if module in answers:
                modules.add(module)
        if isinstance(node, ast.Attribute):
            names.add(node.attr)
        elif isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id == "__import__":
            notes.append("imports modules by name (__import__)")
        elif isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id == "getattr":
            names.update(a.value for a in node.args[1:2] if isinstance(a, ast.Constant) and isinstance(a.value, str))
    for module in sorted(modules):
        for name in answers[module]:
            if name in names:
                notes.append(f"uses {module}.{name}, minippo's own version of the exercise")
    return list(dict.fromkeys(notes))
