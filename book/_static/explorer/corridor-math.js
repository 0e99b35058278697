/*
 * The corridor toy's math, a line-for-line port of minippo/toys/corridor.py (read that module's docstrings for the
 * derivations). The same operations in the same order, so that a test can run both on the same settings and
 * require the trajectories to agree to 1e-9. Like the Python, it computes e^x, log x and cos x from + - * /
 * alone (see the end of the file), so the two agree bit for bit. Plain JavaScript, no dependencies; loads in a
 * page (as window.CorridorMath) and in Node (require).
 *
 *   trap <- start - s1 - s2 - s3 - s4 -> goal      reward +1 at the goal, -1 in the trap, gamma = 0.97
 */
(function (root, factory) {
  "use strict";
  if (typeof module === "object" && module.exports) {
    module.exports = factory();
  } else {
    root.CorridorMath = factory();
  }
})(typeof self !== "undefined" ? self : this, function () {
  "use strict";

  var N_STATES = 5;
  var N_ACTIONS = 2;
  var LEFT = 0;
  var RIGHT = 1;
  var GAMMA = 0.97;
  var GOAL_REWARD = 1.0;
  var TRAP_REWARD = -1.0;
  var OBJECTIVES = ["clip", "cpi", "klpen"];
  var LOGIT_BOUND = 25.0;

  var DEFAULTS = {
    objective: "clip",
    epsilon: 0.2,
    step_size: 0.3,
    epochs: 10,
    noise: 0.2,
    seed: 1,
    kl_beta: 1.0,
    kl_target: 0.01,
    gamma: GAMMA,
  };
  var PRESETS = {
    clip: { objective: "clip", epsilon: 0.2, epochs: 10, step_size: 0.3, noise: 0.2, seed: 1 },
    noclip: { objective: "cpi", epsilon: 0.2, epochs: 40, step_size: 0.3, noise: 0.2, seed: 1 },
    hugestep: { objective: "clip", epsilon: 0.2, epochs: 40, step_size: 3.0, noise: 0.2, seed: 1 },
  };
  var PRESET_TITLES = {
    clip: "Clipped objective",
    noclip: "No clip, many epochs",
    hugestep: "Clip, huge step, 40 epochs",
  };
  var LIMITS = { epsilon: [0.05, 0.5], step_size: [0.001, 100.0], epochs: [1, 100], noise: [0.0, 1.0] };

  // ------------------------------------------------------------------ the policy

  function softmaxPolicy(logits) {
    var probs = [];
    for (var s = 0; s < logits.length; s++) {
      var row = logits[s];
      var top = Math.max.apply(null, row);
      var exps = [];
      var total = 0;
      for (var a = 0; a < row.length; a++) exps.push(exp(row[a] - top));
      for (a = 0; a < exps.length; a++) total += exps[a];
      var p = [];
      for (a = 0; a < exps.length; a++) p.push(exps[a] / total);
      probs.push(p);
    }
    return probs;
  }

  // ------------------------------------------------------------------ exact values

  function solveTridiagonal(lower, diag, upper, rhs) {
    var n = diag.length;
    var c = new Array(n).fill(0.0);
    var y = new Array(n).fill(0.0);
    c[0] = upper[0] / diag[0];
    y[0] = rhs[0] / diag[0];
    for (var i = 1; i < n; i++) {
      var denom = diag[i] - lower[i] * c[i - 1];
      c[i] = i < n - 1 ? upper[i] / denom : 0.0;
      y[i] = (rhs[i] - lower[i] * y[i - 1]) / denom;
    }
    var x = new Array(n).fill(0.0);
    x[n - 1] = y[n - 1];
    for (i = n - 2; i >= 0; i--) x[i] = y[i] - c[i] * x[i + 1];
    return x;
  }

  function ones(n) {
    return new Array(n).fill(1.0);
  }

  function stateValues(probs, gamma) {
    var lower = new Array(N_STATES).fill(0.0);
    var upper = new Array(N_STATES).fill(0.0);
    var rhs = new Array(N_STATES).fill(0.0);
    for (var s = 0; s < N_STATES; s++) {
      if (s > 0) lower[s] = -gamma * probs[s][LEFT];
      else rhs[s] += probs[s][LEFT] * TRAP_REWARD;
      if (s < N_STATES - 1) upper[s] = -gamma * probs[s][RIGHT];
      else rhs[s] += probs[s][RIGHT] * GOAL_REWARD;
    }
    return solveTridiagonal(lower, ones(N_STATES), upper, rhs);
  }

  function actionValues(values, gamma) {
    var q = [];
    for (var s = 0; s < N_STATES; s++) {
      var left = s === 0 ? TRAP_REWARD : gamma * values[s - 1];
      var right = s === N_STATES - 1 ? GOAL_REWARD : gamma * values[s + 1];
      q.push([left, right]);
    }
    return q;
  }

  function advantagesOf(probs, q, values) {
    var adv = [];
    for (var s = 0; s < N_STATES; s++) {
      var row = [];
      for (var a = 0; a < N_ACTIONS; a++) row.push(q[s][a] - values[s]);
      adv.push(row);
    }
    return adv;
  }

  function visitation(probs, gamma) {
    var lower = new Array(N_STATES).fill(0.0);
    var upper = new Array(N_STATES).fill(0.0);
    var rhs = new Array(N_STATES).fill(0.0);
    rhs[0] = 1.0;
    for (var s = 0; s < N_STATES; s++) {
      if (s > 0) lower[s] = -gamma * probs[s - 1][RIGHT];
      if (s < N_STATES - 1) upper[s] = -gamma * probs[s + 1][LEFT];
    }
    return solveTridiagonal(lower, ones(N_STATES), upper, rhs);
  }

  function optimalReturn(gamma) {
    var discount = 1.0;
    for (var i = 0; i < N_STATES - 1; i++) discount *= gamma;
    return GOAL_REWARD * discount;
  }

  // ------------------------------------------------------------------ the snapshot and the surrogates

  function copyRows(rows) {
    return rows.map(function (row) {
      return row.slice();
    });
  }

  function Snapshot(logits, gamma, noise, noiseScale) {
    this.logits = copyRows(logits);
    this.probs = softmaxPolicy(this.logits);
    this.values = stateValues(this.probs, gamma);
    this.q = actionValues(this.values, gamma);
    this.exact_advantages = advantagesOf(this.probs, this.q, this.values);
    this.visitation = visitation(this.probs, gamma);
    this.advantages = copyRows(this.exact_advantages);
    if (noise) {
      for (var s = 0; s < N_STATES; s++) {
        for (var a = 0; a < N_ACTIONS; a++) this.advantages[s][a] += noiseScale * noise[s * N_ACTIONS + a];
      }
    }
    var total = 0;
    for (s = 0; s < N_STATES; s++) total += this.visitation[s];
    this.visitation_total = total;
  }

  function ratios(probs, snapshot) {
    var r = [];
    for (var s = 0; s < N_STATES; s++) {
      var row = [];
      for (var a = 0; a < N_ACTIONS; a++) row.push(probs[s][a] / snapshot.probs[s][a]);
      r.push(row);
    }
    return r;
  }

  function klPerState(snapshot, probs) {
    var kls = [];
    for (var s = 0; s < N_STATES; s++) {
      var total = 0;
      for (var a = 0; a < N_ACTIONS; a++) {
        total += snapshot.probs[s][a] * log(snapshot.probs[s][a] / probs[s][a]);
      }
      kls.push(total);
    }
    return kls;
  }

  function meanKl(snapshot, probs) {
    var kls = klPerState(snapshot, probs);
    var total = 0;
    for (var s = 0; s < N_STATES; s++) total += snapshot.visitation[s] * kls[s];
    return total / snapshot.visitation_total;
  }

  function logitGradient(probs, gradLogpRow, s) {
    var total = 0;
    for (var a = 0; a < gradLogpRow.length; a++) total += gradLogpRow[a];
    var grad = [];
    for (var j = 0; j < N_ACTIONS; j++) grad.push(gradLogpRow[j] - probs[s][j] * total);
    return grad;
  }

  function cpiObjective(logits, snapshot) {
    var probs = softmaxPolicy(logits);
    var value = 0.0;
    var grad = [];
    for (var s = 0; s < N_STATES; s++) {
      var row = [];
      for (var a = 0; a < N_ACTIONS; a++) {
        var weight = snapshot.visitation[s] * snapshot.probs[s][a];
        var ratio = probs[s][a] / snapshot.probs[s][a];
        value += weight * ratio * snapshot.advantages[s][a];
        row.push(weight * ratio * snapshot.advantages[s][a]);
      }
      grad.push(logitGradient(probs, row, s));
    }
    return [value, grad];
  }

  function clipObjective(logits, snapshot, epsilon) {
    var probs = softmaxPolicy(logits);
    var value = 0.0;
    var grad = [];
    for (var s = 0; s < N_STATES; s++) {
      var row = [];
      for (var a = 0; a < N_ACTIONS; a++) {
        var weight = snapshot.visitation[s] * snapshot.probs[s][a];
        var ratio = probs[s][a] / snapshot.probs[s][a];
        var advantage = snapshot.advantages[s][a];
        var unclipped = ratio * advantage;
        var clipped = Math.min(Math.max(ratio, 1.0 - epsilon), 1.0 + epsilon) * advantage;
        if (unclipped <= clipped) {
          value += weight * unclipped;
          row.push(weight * unclipped);
        } else {
          value += weight * clipped;
          row.push(0.0);
        }
      }
      grad.push(logitGradient(probs, row, s));
    }
    return [value, grad];
  }

  function klPenaltyObjective(logits, snapshot, beta) {
    var out = cpiObjective(logits, snapshot);
    var value = out[0];
    var grad = out[1];
    var probs = softmaxPolicy(logits);
    var kls = klPerState(snapshot, probs);
    for (var s = 0; s < N_STATES; s++) {
      value -= beta * snapshot.visitation[s] * kls[s];
      for (var j = 0; j < N_ACTIONS; j++) {
        grad[s][j] -= beta * snapshot.visitation[s] * (probs[s][j] - snapshot.probs[s][j]);
      }
    }
    return [value, grad];
  }

  function clippedMask(probs, snapshot, epsilon) {
    var mask = [];
    for (var s = 0; s < N_STATES; s++) {
      var row = [];
      for (var a = 0; a < N_ACTIONS; a++) {
        var ratio = probs[s][a] / snapshot.probs[s][a];
        var advantage = snapshot.advantages[s][a];
        row.push(ratio * advantage > Math.min(Math.max(ratio, 1.0 - epsilon), 1.0 + epsilon) * advantage);
      }
      mask.push(row);
    }
    return mask;
  }

  function clipFraction(probs, snapshot, epsilon) {
    var total = 0.0;
    for (var s = 0; s < N_STATES; s++) {
      for (var a = 0; a < N_ACTIONS; a++) {
        if (Math.abs(probs[s][a] / snapshot.probs[s][a] - 1.0) > epsilon) {
          total += snapshot.visitation[s] * snapshot.probs[s][a];
        }
      }
    }
    return total / snapshot.visitation_total;
  }

  function klLimit(epsilon) {
    return epsilon * epsilon;
  }

  // eq. 8's rule for beta: minippo.losses.adaptive_beta, which the Python corridor uses
  function adaptiveBeta(beta, kl, klTarget) {
    if (kl < klTarget / 1.5) return beta / 2.0;
    if (kl > klTarget * 1.5) return beta * 2.0;
    return beta;
  }

  // ------------------------------------------------------------------ seeded noise (mulberry32 + Box-Muller)

  function Noise(seed) {
    this.state = seed >>> 0;
  }
  Noise.prototype.uniform = function () {
    this.state = (this.state + 0x6d2b79f5) >>> 0;
    var t = this.state;
    t = Math.imul(t ^ (t >>> 15), t | 1) >>> 0;
    t = (t ^ ((t + Math.imul(t ^ (t >>> 7), t | 61)) >>> 0)) >>> 0;
    return ((t ^ (t >>> 14)) >>> 0) / 4294967296.0;
  };
  Noise.prototype.normal = function () {
    var u1 = 1.0 - this.uniform();
    var u2 = this.uniform();
    return Math.sqrt(-2.0 * log(u1)) * cosTurns(u2);
  };

  // ------------------------------------------------------------------ Algorithm 1 on the corridor

  function checkSettings(settings) {
    var merged = {};
    var key;
    for (key in DEFAULTS) merged[key] = DEFAULTS[key];
    for (key in settings) {
      if (!Object.prototype.hasOwnProperty.call(DEFAULTS, key)) throw new Error("unknown corridor setting: " + key);
      merged[key] = settings[key];
    }
    if (OBJECTIVES.indexOf(merged.objective) < 0) throw new Error("objective must be one of " + OBJECTIVES.join(", "));
    for (key in LIMITS) {
      var v = merged[key];
      if (typeof v !== "number" || !(v >= LIMITS[key][0] && v <= LIMITS[key][1])) {
        throw new Error(key + " must be a number in [" + LIMITS[key][0] + ", " + LIMITS[key][1] + "]");
      }
    }
    if (merged.epochs !== Math.floor(merged.epochs)) throw new Error("epochs must be a whole number");
    return merged;
  }

  function Explorer(settings) {
    this.settings = checkSettings(settings || {});
    this.noise = new Noise(this.settings.seed);
    this.logits = [];
    for (var s = 0; s < N_STATES; s++) this.logits.push(new Array(N_ACTIONS).fill(0.0));
    this.beta = this.settings.kl_beta;
    this.round = 0;
    this.tick_count = 0;
    this.optimal = optimalReturn(this.settings.gamma);
    this.beginRound();
  }

  Explorer.prototype.set = function (key, value) {
    var settings = {};
    for (var k in this.settings) settings[k] = this.settings[k];
    settings[key] = value;
    this.settings = checkSettings(settings);
  };

  Explorer.prototype.beginRound = function () {
    var draws = [];
    for (var i = 0; i < N_STATES * N_ACTIONS; i++) draws.push(this.noise.normal());
    this.snapshot = new Snapshot(this.logits, this.settings.gamma, draws, this.settings.noise);
    this.round += 1;
    this.epoch = 0;
  };

  Explorer.prototype.endRound = function () {
    if (this.settings.objective === "klpen") {
      this.beta = adaptiveBeta(this.beta, this.kl(), this.settings.kl_target);
    }
    this.beginRound();
  };

  Explorer.prototype.objective = function (logits) {
    logits = logits || this.logits;
    var name = this.settings.objective;
    if (name === "clip") return clipObjective(logits, this.snapshot, this.settings.epsilon);
    if (name === "klpen") return klPenaltyObjective(logits, this.snapshot, this.beta);
    return cpiObjective(logits, this.snapshot);
  };

  Explorer.prototype.tick = function () {
    if (this.epoch >= this.settings.epochs) this.endRound();
    var grad = this.objective()[1];
    var step = this.settings.step_size;
    var next = [];
    for (var s = 0; s < N_STATES; s++) {
      var row = [];
      for (var a = 0; a < N_ACTIONS; a++) {
        row.push(Math.min(Math.max(this.logits[s][a] + step * grad[s][a], -LOGIT_BOUND), LOGIT_BOUND));
      }
      next.push(row);
    }
    this.logits = next;
    this.epoch += 1;
    this.tick_count += 1;
    return this.record();
  };

  Explorer.prototype.probs = function () {
    return softmaxPolicy(this.logits);
  };

  Explorer.prototype.kl = function () {
    return meanKl(this.snapshot, this.probs());
  };

  Explorer.prototype.record = function () {
    var probs = this.probs();
    var epsilon = this.settings.epsilon;
    var kl = meanKl(this.snapshot, probs);
    var value = this.objective()[0];
    return {
      tick: this.tick_count,
      round: this.round,
      epoch: this.epoch,
      objective: this.settings.objective,
      logits: copyRows(this.logits),
      probs: probs,
      ratios: ratios(probs, this.snapshot),
      advantages: copyRows(this.snapshot.advantages),
      clipped:
        this.settings.objective === "clip"
          ? clippedMask(probs, this.snapshot, epsilon)
          : [0, 1, 2, 3, 4].map(function () {
              return [false, false];
            }),
      clip_fraction: clipFraction(probs, this.snapshot, epsilon),
      surrogate: value,
      return: stateValues(probs, this.settings.gamma)[0],
      kl: kl,
      kl_limit: klLimit(epsilon),
      held: kl <= klLimit(epsilon),
      beta: this.beta,
    };
  };

  function run(settings, ticks, changes) {
    settings = Object.assign({}, settings || {});
    var preset = settings.preset;
    delete settings.preset;
    if (preset !== undefined) {
      if (!PRESETS[preset]) throw new Error("preset must be one of " + Object.keys(PRESETS).join(", "));
      settings = Object.assign({}, PRESETS[preset], settings);
    }
    var explorer = new Explorer(settings);
    changes = changes || {};
    var trace = [];
    for (var tick = 1; tick <= ticks; tick++) {
      var change = changes[tick] || changes[String(tick)];
      if (change) for (var key in change) explorer.set(key, change[key]);
      trace.push(explorer.tick());
    }
    return trace;
  }

  // ------------------------------------------------------------------ e^x, log x, cos x from + - * / alone

  var LN2_HI = 6.9314718036912381649e-1;
  var LN2_LO = 1.90821492927058770002e-10;
  var INV_LN2 = 1.442695040888963387;
  var SQRT_HALF = 0.7071067811865475244;
  var HALF_PI = 1.57079632679489661923;

  function ldexp(x, k) {
    // multiplying by 2 or 1/2 is exact away from the subnormal range, which exp's callers never reach
    for (; k > 0; k--) x *= 2.0;
    for (; k < 0; k++) x *= 0.5;
    return x;
  }

  function frexp(x) {
    // x = m 2^e with m in [1/2, 1), for a positive finite x
    var e = 0;
    while (x >= 1.0) {
      x *= 0.5;
      e += 1;
    }
    while (x < 0.5) {
      x *= 2.0;
      e -= 1;
    }
    return [x, e];
  }

  function exp(x) {
    if (x < -708.0) return 0.0;
    var k = Math.floor(x * INV_LN2 + 0.5);
    var r = x - k * LN2_HI - k * LN2_LO;
    var series = 1.0;
    for (var n = 14; n > 0; n--) series = 1.0 + (series * r) / n;
    return ldexp(series, k);
  }

  function log(x) {
    var me = frexp(x);
    var m = me[0];
    var e = me[1];
    if (m < SQRT_HALF) {
      m *= 2.0;
      e -= 1;
    }
    var s = (m - 1.0) / (m + 1.0);
    var s2 = s * s;
    var series = 1.0 / 21.0;
    for (var n = 19; n > 0; n -= 2) series = 1.0 / n + s2 * series;
    return e * LN2_HI + (e * LN2_LO + 2.0 * s * series);
  }

  function cosQuarter(f) {
    var a = f * HALF_PI;
    var a2 = a * a;
    var series = 1.0;
    for (var k = 12; k > 0; k--) series = 1.0 - (a2 * series) / ((2 * k - 1) * (2 * k));
    return series;
  }

  function sinQuarter(f) {
    var a = f * HALF_PI;
    var a2 = a * a;
    var series = 1.0;
    for (var k = 12; k > 0; k--) series = 1.0 - (a2 * series) / (2 * k * (2 * k + 1));
    return a * series;
  }

  function cosTurns(u) {
    var quarter = u * 4.0;
    var q = Math.floor(quarter);
    var f = quarter - q;
    if (q === 0) return cosQuarter(f);
    if (q === 1) return -sinQuarter(f);
    if (q === 2) return -cosQuarter(f);
    return sinQuarter(f);
  }

  return {
    N_STATES: N_STATES,
    N_ACTIONS: N_ACTIONS,
    LEFT: LEFT,
    RIGHT: RIGHT,
    GAMMA: GAMMA,
    GOAL_REWARD: GOAL_REWARD,
    TRAP_REWARD: TRAP_REWARD,
    OBJECTIVES: OBJECTIVES,
    DEFAULTS: DEFAULTS,
    PRESETS: PRESETS,
    PRESET_TITLES: PRESET_TITLES,
    LIMITS: LIMITS,
    softmaxPolicy: softmaxPolicy,
    solveTridiagonal: solveTridiagonal,
    stateValues: stateValues,
    actionValues: actionValues,
    advantagesOf: advantagesOf,
    visitation: visitation,
    optimalReturn: optimalReturn,
    Snapshot: Snapshot,
    ratios: ratios,
    klPerState: klPerState,
    meanKl: meanKl,
    cpiObjective: cpiObjective,
    clipObjective: clipObjective,
    klPenaltyObjective: klPenaltyObjective,
    clippedMask: clippedMask,
    clipFraction: clipFraction,
    klLimit: klLimit,
    adaptiveBeta: adaptiveBeta,
    Noise: Noise,
    checkSettings: checkSettings,
    Explorer: Explorer,
    run: run,
    exp: exp,
    log: log,
    cosTurns: cosTurns,
    LOGIT_BOUND: LOGIT_BOUND,
  };
});
