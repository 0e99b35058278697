"""The explorer's JavaScript port of the corridor (book/_static/explorer/corridor-math.js), run under Node.js, must
play the same trajectory as minippo/toys/corridor.py: every number of every tick within 1e-9, every flag equal."""

import json
import math
import os
import shutil
import subprocess
from pathlib import Path

import pytest

from minippo.toys import corridor as cd

ROOT = Path(__file__).resolve().parents[1]
MATH_JS = ROOT / "book" / "_static" / "explorer" / "corridor-math.js"
NODE = shutil.which("node")

# reads {"settings", "ticks", "changes"} as JSON on stdin and writes the JavaScript trace as JSON
RUNNER = """
const corridor = require(process.argv[1]);
let input = "";
process.stdin.on("data", (chunk) => (input += chunk));
process.stdin.on("end", () => {
  const job = JSON.parse(input);
  process.stdout.write(JSON.stringify(corridor.run(job.settings, job.ticks, job.changes)));
});
"""

CASES = {
    "clip preset": ({"preset": "clip"}, 600, {}),
    "no-clip preset": ({"preset": "noclip"}, 800, {}),
    "huge-step preset": ({"preset": "hugestep"}, 800, {}),
    "KL penalty": ({"preset": "clip", "objective": "klpen"}, 400, {}),
    "strong noise, another seed": ({"preset": "hugestep", "noise": 0.5, "seed": 9}, 800, {}),
    "no noise": ({"preset": "clip", "noise": 0.0}, 300, {}),
    "mid-run switches": (
        {"preset": "noclip"},
        700,
        {60: {"objective": "clip"}, 200: {"epsilon": 0.1, "epochs": 7}, 333: {"objective": "klpen", "noise": 0.4}},
    ),
    "the logit bound": ({"objective": "cpi", "step_size": 100.0, "noise": 1.0, "epochs": 100, "seed": 5}, 300, {}),
}


def node_available():
    if NODE is None:
        if os.environ.get("CI") == "true":
            pytest.fail("node (Node.js) is not on PATH: the JavaScript port cannot be checked")
        pytest.skip("node (Node.js) is not installed")


def run_javascript(settings, ticks, changes):
    job = {"settings": settings, "ticks": ticks, "changes": {str(k): v for k, v in changes.items()}}
    result = subprocess.run(
        [NODE, "-e", RUNNER, str(MATH_JS)], input=json.dumps(job), capture_output=True, text=True, timeout=120
    )
    assert result.returncode == 0, result.stderr
    return json.loads(result.stdout, parse_int=float)


def largest_difference(python, javascript, where="trace"):
    """The largest |a − b| / max(1, |b|) over two nested structures, which must have the same shape and flags."""
    if isinstance(python, bool) or isinstance(python, str):
        assert python == javascript, f"{where}: {python!r} != {javascript!r}"
        return 0.0
    if isinstance(python, (int, float)):
        assert isinstance(javascript, (int, float)) and not isinstance(javascript, bool), where
        return abs(python - javascript) / max(1.0, abs(javascript))
    if isinstance(python, list):
        assert isinstance(javascript, list) and len(python) == len(javascript), f"{where}: lengths differ"
        pairs = enumerate(zip(python, javascript))
        return max([largest_difference(p, j, f"{where}[{i}]") for i, (p, j) in pairs] + [0.0])
    assert isinstance(python, dict) and set(python) == set(javascript), f"{where}: keys differ"
    return max(largest_difference(python[key], javascript[key], f"{where}.{key}") for key in python)


@pytest.mark.parametrize("case", list(CASES))
def test_javascript_port_plays_the_same_trajectory(case):
    node_available()
    settings, ticks, changes = CASES[case]
    python = cd.run(settings, ticks, changes)
    javascript = run_javascript(settings, ticks, changes)
    assert len(javascript) == ticks
    difference = largest_difference(python, javascript)
    assert difference <= 1e-9, f"{case}: the trajectories differ by {difference:.3g}"


def test_javascript_port_draws_the_same_noise_and_elementary_functions():
    node_available()
    script = """
const m = require(process.argv[1]);
const noise = new m.Noise(2024);
const out = {normals: [], uniforms: [], exp: [], log: [], cos: []};
for (let i = 0; i < 200; i++) out.normals.push(noise.normal());
const other = new m.Noise(4294967295);
for (let i = 0; i < 200; i++) out.uniforms.push(other.uniform());
for (let i = 0; i < 200; i++) {
  out.exp.push(m.exp(-60 + 0.6 * i + 0.0123));
  out.log.push(m.log(Math.pow(1.37, i - 100)));
  out.cos.push(m.cosTurns(i / 200 + 0.0017));
}
process.stdout.write(JSON.stringify(out));
"""
    result = subprocess.run([NODE, "-e", script, str(MATH_JS)], capture_output=True, text=True, timeout=60)
    assert result.returncode == 0, result.stderr
    js = json.loads(result.stdout, parse_int=float)
    noise = cd.Noise(2024)
    assert js["normals"] == [noise.normal() for _ in range(200)]  # bit for bit
    other = cd.Noise(4294967295)
    assert js["uniforms"] == [other.uniform() for _ in range(200)]
    assert js["exp"] == [cd.exp(-60 + 0.6 * i + 0.0123) for i in range(200)]
    # the arguments of log come from JavaScript's Math.pow, so compare against Python's log of the same numbers
    assert all(math.isclose(a, math.log(1.37 ** (i - 100)), rel_tol=1e-14) for i, a in enumerate(js["log"]))
    assert js["cos"] == [cd.cos_turns(i / 200 + 0.0017) for i in range(200)]
