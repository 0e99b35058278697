/*
 * The corridor explorer: PPO's Algorithm 1 on the five-state corridor, in the reader's browser.
 *
 * Every <div class="corridor-explorer" data-preset="clip|noclip|hugestep"> on the page becomes an explorer when
 * the page has loaded; a page without one is left alone. The math is minippo/toys/corridor.py, ported line for line
 * to corridor-math.js (loaded from beside this file), and a test checks that the two play the same trajectory.
 * This file only draws: the playback speed sets how many ticks are played per second, never what a tick does.
 *
 * Optional attributes: data-speed="<ticks per second>" starts at another playback speed; data-objective="clip|cpi|klpen"
 * starts the preset with another objective (the KL-penalty chapter starts the clip preset on L^KLPEN).
 */
(function () {
  "use strict";
  if (typeof document === "undefined") return; // required by Node: nothing to draw

  const SCRIPT =
    document.currentScript ||
    Array.prototype.find.call(document.scripts, (tag) => /corridor-explorer\.js/.test(tag.src)) ||
    null;
  const COLORS = { clay: "#c8643b", sage: "#7d9a72", ink: "#2f2a26", slate: "#4f6d8f" };
  const STEP_SIZES = [0.03, 0.05, 0.1, 0.2, 0.3, 0.5, 1, 2, 3, 5, 10];
  const SPEEDS = [1, 2, 5, 10, 20, 40, 80, 160, 320];
  const DEFAULT_SPEED = 20;
  const MAX_ROUNDS = 150;
  const MAX_LOG = 80;
  const OBJECTIVE_LABELS = {
    clip: "clip (L<sup>CLIP</sup>)",
    cpi: "no clip (L<sup>CPI</sup>)",
    klpen: "KL penalty (L<sup>KLPEN</sup>)",
  };
  const OBJECTIVE_TEXT = { clip: "clip (L^CLIP)", cpi: "no clip (L^CPI)", klpen: "KL penalty (L^KLPEN)" };
  const STATE_NAMES = ["start", "s1", "s2", "s3", "s4"];
  const ACTION_NAMES = ["left", "right"];
  let uid = 0;

  // ---------------------------------------------------------------- small helpers

  function el(tag, attrs, children) {
    const node = document.createElement(tag);
    for (const key in attrs || {}) {
      if (key === "text") node.textContent = attrs[key];
      else if (key === "html") node.innerHTML = attrs[key];
      else node.setAttribute(key, attrs[key]);
    }
    for (const child of children || []) node.appendChild(child);
    return node;
  }

  function svg(tag, attrs) {
    const node = document.createElementNS("http://www.w3.org/2000/svg", tag);
    for (const key in attrs || {}) node.setAttribute(key, attrs[key]);
    return node;
  }

  function fmt(x, digits) {
    if (!isFinite(x)) return String(x);
    return x.toFixed(digits === undefined ? 3 : digits);
  }

  // β lives on powers of two times its start and may halve far below 0.01: three significant digits, or a power of ten
  function fmtBeta(beta) {
    return beta >= 0.01 ? String(Number(beta.toPrecision(3))) : minus(beta.toExponential(1));
  }

  function signed(x, digits) {
    return (x >= 0 ? "+" : "\u2212") + fmt(Math.abs(x), digits);
  }

  function minus(text) {
    return text.replace(/-/g, "\u2212");
  }

  function percent(x) {
    return Math.round(100 * x) + "%";
  }

  function nearestIndex(list, value) {
    let best = 0;
    for (let i = 1; i < list.length; i++) if (Math.abs(list[i] - value) < Math.abs(list[best] - value)) best = i;
    return best;
  }

  // ---------------------------------------------------------------- one explorer

  function CorridorExplorer(root, M) {
    this.root = root;
    this.M = M;
    this.id = "corridor-explorer-" + ++uid;
    const preset = M.PRESETS[root.getAttribute("data-preset")] ? root.getAttribute("data-preset") : "clip";
    const speed = Number(root.getAttribute("data-speed"));
    this.speed = speed > 0 ? speed : DEFAULT_SPEED;
    this.presetName = preset;
    this.settings = Object.assign({}, M.DEFAULTS, M.PRESETS[preset]);
    const objective = root.getAttribute("data-objective");
    if (M.OBJECTIVES.indexOf(objective) >= 0) this.settings.objective = objective;
    this.selected = 0;
    this.dragFrom = {}; // a slider's setting when its drag began: the log gets one line when the drag ends
    this.hovered = null;
    this.playing = false;
    this.frame = null;
    this.build();
    this.reset(false);
    const start = objective && this.settings.objective !== M.PRESETS[preset].objective ? ", on " + OBJECTIVE_TEXT[objective] : "";
    this.log("Preset \u201c" + M.PRESET_TITLES[preset] + "\u201d" + start + ". Press play, or step one epoch at a time.");
    root.setAttribute("data-ready", "true");
  }

  CorridorExplorer.prototype.build = function () {
    const M = this.M;
    const root = this.root;
    const id = this.id;
    root.innerHTML = "";
    root.classList.add("ce");
    root.setAttribute("role", "group");
    root.setAttribute("aria-label", "Corridor explorer: PPO's clipped objective on a five-state corridor");

    // presets
    const presets = el("div", { class: "ce-presets", role: "group", "aria-label": "Presets" });
    presets.appendChild(el("span", { class: "ce-label", text: "Presets" }));
    this.presetButtons = {};
    for (const name of Object.keys(M.PRESETS)) {
      const button = el("button", { type: "button", class: "ce-preset", "data-preset": name, text: M.PRESET_TITLES[name] });
      button.addEventListener("click", () => this.applyPreset(name));
      this.presetButtons[name] = button;
      presets.appendChild(button);
    }
    root.appendChild(presets);

    // status: the light and the numbers
    this.light = el("div", { class: "ce-light", role: "status", "aria-live": "polite" }, [
      el("span", { class: "ce-light-lamp", "aria-hidden": "true" }),
      el("span", { class: "ce-light-text" }),
    ]);
    this.status = el("div", { class: "ce-status" });
    this.statusParts = {};
    for (const [key, label] of [
      ["round", "round"],
      ["epoch", "epoch"],
      ["kl", "KL"],
      ["return", "return"],
      ["clipped", "clipped"],
      ["beta", "\u03b2"],
    ]) {
      const value = el("span", { class: "ce-value ce-" + key });
      const name = el("span", { class: "ce-stat-label", text: label + " " });
      const part = el("span", { class: "ce-stat ce-stat-" + key }, [name, value]);
      this.statusParts[key] = { part: part, label: name, value: value };
      this.status.appendChild(part);
    }
    root.appendChild(el("div", { class: "ce-top" }, [this.light, this.status]));

    // the corridor
    const corridor = el("div", { class: "ce-corridor", role: "group", "aria-label": "The corridor: probability of moving right in each state" });
    corridor.appendChild(el("div", { class: "ce-end ce-trap", html: "<span>trap</span><small>\u22121</small>", "aria-hidden": "true" }));
    this.stateButtons = [];
    for (let s = 0; s < M.N_STATES; s++) {
      const fill = el("span", { class: "ce-bar-fill" });
      const pct = el("span", { class: "ce-pct" });
      const button = el("button", { type: "button", class: "ce-state", "aria-pressed": "false" }, [
        el("span", { class: "ce-state-name", text: STATE_NAMES[s] }),
        el("span", { class: "ce-bar", "aria-hidden": "true" }, [fill]),
        pct,
      ]);
      button.addEventListener("click", () => this.select(s));
      button.addEventListener("focus", () => this.hover(s));
      button.addEventListener("blur", () => this.hover(null));
      button.addEventListener("mouseenter", () => this.hover(s));
      button.addEventListener("mouseleave", () => this.hover(null));
      this.stateButtons.push({ button: button, fill: fill, pct: pct });
      corridor.appendChild(button);
    }
    corridor.appendChild(el("div", { class: "ce-end ce-goal", html: "<span>goal</span><small>+1</small>", "aria-hidden": "true" }));
    root.appendChild(el("div", { class: "ce-caption", text: "P(right) in each state (bars); moving left from start falls into the trap. Click or focus a state to inspect it." }));
    root.appendChild(corridor);

    // the ratio track and the table for the shown state, and the chart
    const panels = el("div", { class: "ce-panels" });
    const statePanel = el("div", { class: "ce-panel ce-state-panel" });
    this.trackTitle = el("div", { class: "ce-panel-title" });
    statePanel.appendChild(this.trackTitle);
    statePanel.appendChild(this.buildTrack());
    this.table = this.buildTable();
    statePanel.appendChild(this.table.node);
    panels.appendChild(statePanel);

    const chartPanel = el("div", { class: "ce-panel ce-chart-panel" });
    chartPanel.appendChild(el("div", { class: "ce-panel-title", html: '<span class="ce-key ce-key-return"></span>return V(start) &nbsp; <span class="ce-key ce-key-kl"></span>KL(snapshot, policy)' }));
    chartPanel.appendChild(this.buildChart());
    panels.appendChild(chartPanel);
    root.appendChild(panels);

    // controls
    const controls = el("div", { class: "ce-controls" });
    const transport = el("div", { class: "ce-transport", role: "group", "aria-label": "Playback" });
    this.playButton = el("button", { type: "button", class: "ce-play", "aria-pressed": "false", text: "\u25b6 Play" });
    this.playButton.addEventListener("click", () => (this.playing ? this.pause() : this.play()));
    const stepButton = el("button", { type: "button", class: "ce-step", text: "Step", title: "one gradient step (one epoch)" });
    stepButton.addEventListener("click", () => {
      this.pause();
      this.advance(1);
      this.render();
    });
    const resetButton = el("button", { type: "button", class: "ce-reset", text: "Reset" });
    resetButton.addEventListener("click", () => {
      this.pause();
      this.reset(true);
    });
    transport.append(this.playButton, stepButton, resetButton);
    controls.appendChild(transport);

    const objective = el("fieldset", { class: "ce-objective" }, [el("legend", { text: "Objective" })]);
    this.objectiveInputs = {};
    for (const name of M.OBJECTIVES) {
      const input = el("input", { type: "radio", name: id + "-objective", value: name, id: id + "-objective-" + name });
      input.addEventListener("change", () => input.checked && this.change("objective", name));
      this.objectiveInputs[name] = input;
      objective.appendChild(el("label", { for: input.id, class: "ce-radio" }, [input, el("span", { html: OBJECTIVE_LABELS[name] })]));
    }
    controls.appendChild(objective);

    const sliders = el("div", { class: "ce-sliders" });
    this.sliders = {};
    this.addSlider(sliders, "epsilon", "clip range \u03b5", 0.05, 0.5, 0.01, (v) => v, (v) => fmt(v, 2));
    this.addSlider(sliders, "step_size", "step size \u03b1", 0, STEP_SIZES.length - 1, 1, (i) => STEP_SIZES[i], (v) => String(v), (v) => nearestIndex(STEP_SIZES, v));
    this.addSlider(sliders, "epochs", "epochs K", 1, 50, 1, (v) => v, (v) => String(v));
    this.addSlider(sliders, "noise", "advantage noise \u03c3", 0, 1, 0.05, (v) => v, (v) => fmt(v, 2));
    this.addSlider(sliders, "speed", "playback speed (ticks/s)", 0, SPEEDS.length - 1, 1, (i) => SPEEDS[i], (v) => String(v), (v) => nearestIndex(SPEEDS, v));
    controls.appendChild(sliders);
    root.appendChild(controls);

    // event log
    this.logList = el("ol", { class: "ce-log-list", reversed: "reversed" });
    root.appendChild(
      el("div", { class: "ce-log" }, [
        el("div", { class: "ce-panel-title", text: "Event log" }),
        el("div", { class: "ce-log-scroll", role: "log", "aria-live": "polite", tabindex: "0", "aria-label": "Event log" }, [this.logList]),
      ])
    );
    root.appendChild(
      el("p", {
        class: "ce-note",
        text:
          "One tick is one gradient step \u03b8 \u2190 \u03b8 + \u03b1\u2207L on the frozen snapshot \u03b8_old; after K epochs the round ends and the snapshot refreshes (Algorithm 1). " +
          "The advantages are solved exactly each round (\u03b3 = 0.97) and the noise slider adds Gaussian noise to them, standing in for estimating them from samples. " +
          "The light reads \u201cbroken\u201d while KL(snapshot, policy), averaged over the states the snapshot visits, exceeds \u03b5\u00b2, twice the KL of a policy whose ratios all sit on the band\u2019s edge. " +
          "Playback speed changes the animation only, never the math.",
      })
    );

  };

  CorridorExplorer.prototype.addSlider = function (parent, key, label, min, max, step, fromSlider, show, toSlider) {
    const inputId = this.id + "-" + key;
    const input = el("input", { type: "range", id: inputId, min: min, max: max, step: step, "data-setting": key });
    const output = el("output", { for: inputId, class: "ce-output" });
    const update = () => {
      const value = fromSlider(Number(input.value));
      output.textContent = show(value);
      input.setAttribute("aria-valuetext", show(value));
      return value;
    };
    input.addEventListener("input", () => {
      const value = update();
      if (key === "speed") {
        this.speed = value;
        return;
      }
      // the math follows every intermediate value of a drag; the log waits for its end ("change")
      if (!(key in this.dragFrom)) this.dragFrom[key] = this.settings[key];
      this.change(key, value, false);
    });
    input.addEventListener("change", () => {
      if (!(key in this.dragFrom)) return;
      const from = this.dragFrom[key];
      delete this.dragFrom[key];
      if (from !== this.settings[key]) this.logChange(key, this.settings[key]);
    });
    this.sliders[key] = {
      input: input,
      set: (value) => {
        input.value = toSlider ? toSlider(value) : value;
        update();
      },
    };
    parent.appendChild(el("div", { class: "ce-slider" }, [el("label", { for: inputId, text: label }), input, output]));
  };

  CorridorExplorer.prototype.buildTrack = function () {
    // a label column on the left, then the ratio axis from 0 to 2 with the band [1 - eps, 1 + eps] on it
    const width = 340;
    this.track = { width: width, x0: 126, x1: width - 10, rMax: 2.0 };
    const t = this.track;
    const node = svg("svg", { class: "ce-track", viewBox: "0 0 " + width + " 104", role: "img" });
    this.trackSvg = node;
    const rows = [40, 70];
    for (const y of rows) node.appendChild(svg("line", { x1: t.x0, x2: t.x1, y1: y, y2: y, class: "ce-track-axis" }));
    this.band = svg("rect", { class: "ce-band", y: 24, height: 62, rx: 3 });
    node.appendChild(this.band);
    // the labels grow outwards from the band's edges, so that they never overlap, however narrow the band
    this.bandLow = svg("text", { class: "ce-band-label", y: 18, "text-anchor": "end" });
    this.bandHigh = svg("text", { class: "ce-band-label", y: 18, "text-anchor": "start" });
    node.append(this.bandLow, this.bandHigh);
    const oneX = this.ratioX(1.0);
    node.appendChild(svg("line", { class: "ce-one", x1: oneX, x2: oneX, y1: 24, y2: 86 }));
    const oneLabel = svg("text", { class: "ce-one-label", x: oneX, y: 101, "text-anchor": "middle" });
    oneLabel.textContent = "r = 1 (snapshot)";
    node.appendChild(oneLabel);
    const hollow = svg("text", { class: "ce-axis-label", x: 0, y: 101 });
    hollow.textContent = "\u25cb = clipped";
    node.appendChild(hollow);
    for (const r of [0, 2]) {
      const tick = svg("text", { class: "ce-axis-label", x: this.ratioX(r), y: 101, "text-anchor": "middle" });
      tick.textContent = String(r);
      node.appendChild(tick);
    }
    this.dots = [];
    for (let a = 0; a < 2; a++) {
      const y = rows[a];
      const name = svg("text", { class: "ce-dot-name", x: 0, y: y - 3 });
      name.textContent = ACTION_NAMES[a];
      const label = svg("text", { class: "ce-dot-label", x: 0, y: y + 11 });
      const dot = svg("circle", { class: "ce-dot ce-dot-" + ACTION_NAMES[a], cy: y, r: 6.5 });
      node.append(name, label, dot);
      this.dots.push({ dot: dot, label: label, y: y });
    }
    return node;
  };

  CorridorExplorer.prototype.ratioX = function (r) {
    const t = this.track;
    const clamped = Math.max(0, Math.min(t.rMax, r));
    return t.x0 + ((t.x1 - t.x0) * clamped) / t.rMax;
  };

  CorridorExplorer.prototype.buildTable = function () {
    const body = el("tbody");
    const rows = [];
    for (let a = 0; a < 2; a++) {
      const cells = [0, 1, 2, 3].map(() => el("td"));
      body.appendChild(el("tr", {}, [el("th", { scope: "row", text: ACTION_NAMES[a] })].concat(cells)));
      rows.push(cells);
    }
    const head = el("thead", {}, [
      el("tr", {}, ["action", "prob", "ratio", "\u00c2", "clipped?"].map((h) => el("th", { scope: "col", text: h }))),
    ]);
    const caption = el("caption");
    const node = el("table", { class: "ce-table" }, [caption, head, body]);
    return { node: node, rows: rows, caption: caption };
  };

  CorridorExplorer.prototype.buildChart = function () {
    const c = { w: 320, h: 196, left: 28, right: 290, top: 12, bottom: 164 };
    this.chart = c;
    const node = svg("svg", { class: "ce-chart", viewBox: "0 0 " + c.w + " " + c.h, role: "img" });
    node.appendChild(svg("rect", { class: "ce-chart-bg", x: c.left, y: c.top, width: c.right - c.left, height: c.bottom - c.top }));
    this.chartZero = svg("line", { class: "ce-grid", x1: c.left, x2: c.right });
    this.chartOptimal = svg("line", { class: "ce-optimal", x1: c.left, x2: c.right });
    this.chartLimit = svg("line", { class: "ce-limit", x1: c.left, x2: c.right });
    this.klArea = svg("path", { class: "ce-kl-area" });
    this.klLine = svg("path", { class: "ce-kl-line" });
    this.returnLine = svg("path", { class: "ce-return-line" });
    node.append(this.chartZero, this.chartOptimal, this.klArea, this.klLine, this.chartLimit, this.returnLine);
    this.chartText = {};
    const labels = {
      retTop: { x: c.left - 4, "text-anchor": "end", class: "ce-axis-label ce-axis-return" },
      retZero: { x: c.left - 4, "text-anchor": "end", class: "ce-axis-label ce-axis-return" },
      retBottom: { x: c.left - 4, "text-anchor": "end", class: "ce-axis-label ce-axis-return" },
      optimal: { x: c.left + 4, "text-anchor": "start", class: "ce-axis-label ce-optimal-label" },
      klTop: { x: c.right + 4, "text-anchor": "start", class: "ce-axis-label ce-axis-kl" },
      klZero: { x: c.right + 4, "text-anchor": "start", class: "ce-axis-label ce-axis-kl" },
      limit: { x: c.right - 4, "text-anchor": "end", class: "ce-axis-label ce-limit-label" },
      xLabel: { x: c.left, y: c.h - 14, "text-anchor": "start", class: "ce-axis-label" },
      xEnd: { x: c.right, y: c.h - 14, "text-anchor": "end", class: "ce-axis-label" },
    };
    for (const key in labels) {
      const text = svg("text", labels[key]);
      this.chartText[key] = text;
      node.appendChild(text);
    }
    this.chartText.xLabel.textContent = "ticks (1 tick = 1 epoch)";
    return node;
  };

  // ---------------------------------------------------------------- state changes

  CorridorExplorer.prototype.reset = function (announce) {
    this.explorer = new this.M.Explorer(this.settings);
    this.record = this.explorer.record();
    this.history = [{ ret: this.record.return, kl: 0 }];
    this.roundBroken = false;
    this.lastRoundBroken = false;
    this.brokenRounds = 0;
    this.reached90 = false;
    this.betaRun = null;
    this.finished = false;
    this.syncControls();
    if (announce) this.log("Reset: round 1 starts again from the uniform policy.");
    this.render();
  };

  CorridorExplorer.prototype.applyPreset = function (name) {
    this.pause();
    this.presetName = name;
    this.settings = Object.assign({}, this.M.DEFAULTS, this.M.PRESETS[name]);
    this.reset(false);
    this.log("Preset \u201c" + this.M.PRESET_TITLES[name] + "\u201d loaded; press play.");
  };

  CorridorExplorer.prototype.syncControls = function () {
    const s = this.settings;
    for (const name in this.objectiveInputs) this.objectiveInputs[name].checked = name === s.objective;
    for (const key of ["epsilon", "step_size", "epochs", "noise"]) this.sliders[key].set(s[key]);
    this.sliders.speed.set(this.speed);
    for (const name in this.presetButtons) {
      const matches = Object.keys(this.M.PRESETS[name]).every((k) => this.M.PRESETS[name][k] === s[k]);
      this.presetButtons[name].setAttribute("aria-pressed", String(matches && name === this.presetName));
    }
  };

  CorridorExplorer.prototype.change = function (key, value, announce) {
    if (this.settings[key] === value) return;
    this.settings[key] = value;
    this.explorer.set(key, value);
    if (announce !== false) this.logChange(key, value);
    this.syncControls();
    this.record = this.explorer.record();
    this.render();
  };

  CorridorExplorer.prototype.logChange = function (key, value) {
    const where = "round " + this.explorer.round + ", epoch " + this.explorer.epoch;
    const words = {
      objective: () => "objective \u2192 " + OBJECTIVE_TEXT[value],
      epsilon: () => "\u03b5 \u2192 " + fmt(value, 2) + " (band [" + fmt(1 - value, 2) + ", " + fmt(1 + value, 2) + "], KL limit " + fmt(value * value, 4) + ")",
      step_size: () => "step size \u2192 " + value,
      epochs: () => "K \u2192 " + value + " epochs per round",
      noise: () => "advantage noise \u2192 " + fmt(value, 2) + " (from the next round)",
    };
    this.log(where + ": " + words[key]());
  };

  CorridorExplorer.prototype.select = function (s) {
    this.selected = s;
    this.render();
  };

  CorridorExplorer.prototype.hover = function (s) {
    this.hovered = s;
    this.render();
  };

  CorridorExplorer.prototype.play = function () {
    if (this.finished) this.reset(true);
    this.playing = true;
    this.playButton.setAttribute("aria-pressed", "true");
    this.playButton.textContent = "\u275a\u275a Pause";
    this.root.setAttribute("data-playing", "true");
    let last = null;
    let owed = 0;
    const frame = (now) => {
      if (!this.playing) return;
      if (last !== null) owed += (Math.min(now - last, 250) / 1000) * this.speed;
      else owed = Math.min(1, this.speed / 60);
      last = now;
      const ticks = Math.floor(owed);
      if (ticks > 0) {
        owed -= ticks;
        this.advance(ticks);
        this.render();
      }
      if (this.playing) this.frame = window.requestAnimationFrame(frame);
    };
    this.frame = window.requestAnimationFrame(frame);
  };

  CorridorExplorer.prototype.pause = function () {
    this.playing = false;
    if (this.frame !== null) window.cancelAnimationFrame(this.frame);
    this.frame = null;
    this.playButton.setAttribute("aria-pressed", "false");
    this.playButton.textContent = "\u25b6 Play";
    this.root.setAttribute("data-playing", "false");
  };

  // plays n ticks of the math, noting what the event log should say
  CorridorExplorer.prototype.advance = function (n) {
    const ex = this.explorer;
    if (this.finished) return;
    for (let i = 0; i < n; i++) {
      if (ex.epoch >= ex.settings.epochs) {
        this.endOfRound();
        if (ex.round >= MAX_ROUNDS) {
          this.finished = true;
          this.pause();
          this.log("Round " + ex.round + " was the last of this run; press reset (or play) to start again.");
          return;
        }
      }
      const before = this.record;
      const record = ex.tick();
      this.record = record;
      if (record.objective === "klpen" && record.beta !== before.beta) this.logBeta(before, record);
      this.history.push({ ret: record.return, kl: record.kl });
      if (!record.held && !this.roundBroken) {
        this.roundBroken = true;
        this.brokenRounds += 1;
        this.log(
          "round " + record.round + ", epoch " + record.epoch + ": KL " + fmt(record.kl, 3) + " broke the limit \u03b5\u00b2 = " + fmt(record.kl_limit, 3)
        );
      }
      if (!this.reached90 && record.return >= 0.9 * ex.optimal) {
        this.reached90 = true;
        this.log("round " + record.round + ": return " + fmt(record.return, 3) + " reached 90% of the optimal " + fmt(ex.optimal, 3));
      }
    }
  };

  // eq. 8's rule acted as a round ended, on the KL d the whole round reached. A run of changes in one direction
  // is one line of the log, rewritten in place, so that a β halving round after round cannot flood it.
  CorridorExplorer.prototype.logBeta = function (before, record) {
    const halves = record.beta < before.beta;
    const run = this.betaRun;
    const d = before.kl >= 1e-4 ? fmt(before.kl, 4) : before.kl.toExponential(1);
    if (run && run.halves === halves && run.last === before.round - 1 && this.logList.firstChild === run.item) {
      run.last = before.round;
      run.count += 1;
      run.item.textContent = minus(
        "rounds " + run.first + "\u2013" + run.last + ": KL d " + (halves ? "below d_targ/1.5" : "above 1.5 d_targ") +
          " every round, \u03b2 " + (halves ? "halved " : "doubled ") + run.count + " times to " + fmtBeta(record.beta) +
          " (last d = " + d + ")"
      );
      return;
    }
    const item = this.log(
      "round " + before.round + " ended at KL d = " + d + (halves ? " < d_targ/1.5: \u03b2 halves to " : " > 1.5 d_targ: \u03b2 doubles to ") + fmtBeta(record.beta)
    );
    this.betaRun = { halves: halves, first: before.round, last: before.round, count: 1, item: item };
  };

  CorridorExplorer.prototype.endOfRound = function () {
    const r = this.record;
    if (!this.roundBroken && this.lastRoundBroken) {
      this.log("round " + r.round + ": held again, KL " + fmt(r.kl, 3) + " at the end of the round");
    }
    this.lastRoundBroken = this.roundBroken;
    this.roundBroken = false;
  };

  CorridorExplorer.prototype.log = function (text) {
    const item = el("li", { text: minus(text) });
    this.logList.insertBefore(item, this.logList.firstChild);
    while (this.logList.children.length > MAX_LOG) this.logList.removeChild(this.logList.lastChild);
    return item;
  };

  // ---------------------------------------------------------------- drawing

  CorridorExplorer.prototype.render = function () {
    const M = this.M;
    const rec = this.record;
    const ex = this.explorer;
    const shown = this.hovered === null ? this.selected : this.hovered;

    // light and status line
    const held = rec.held;
    this.root.setAttribute("data-light", held ? "held" : "broken");
    this.light.className = "ce-light " + (held ? "ce-held" : "ce-broken");
    const lightText = held ? "trust region held" : "trust region broken";
    const lightLabel = this.light.lastChild;
    if (lightLabel.textContent !== lightText) lightLabel.textContent = lightText;
    this.light.firstChild.textContent = held ? "\u2713" : "\u2715";
    const p = this.statusParts;
    p.round.value.textContent = String(ex.round);
    p.epoch.value.textContent = ex.epoch + "/" + ex.settings.epochs;
    const klDigits = rec.kl_limit < 0.01 ? 4 : 3; // ε = 0.05 puts the limit at 0.0025, which three digits would round
    p.kl.value.textContent = fmt(rec.kl, klDigits) + " (limit " + fmt(rec.kl_limit, klDigits) + ")";
    p.return.value.textContent = minus(fmt(rec.return, 3)) + " / " + fmt(ex.optimal, 3) + " optimal";
    p.clipped.value.textContent = percent(rec.clip_fraction);
    const clipLabel = ex.settings.objective === "clip" ? "clipped " : "outside band ";
    if (p.clipped.label.textContent !== clipLabel) p.clipped.label.textContent = clipLabel;
    p.beta.value.textContent = fmtBeta(rec.beta);
    p.beta.part.hidden = ex.settings.objective !== "klpen";
    this.root.setAttribute("data-round", String(ex.round));
    this.root.setAttribute("data-epoch", String(ex.epoch));

    // corridor
    for (let s = 0; s < M.N_STATES; s++) {
      const pr = rec.probs[s][1];
      const b = this.stateButtons[s];
      b.fill.style.height = (100 * pr).toFixed(1) + "%";
      b.pct.textContent = percent(pr);
      b.button.setAttribute("aria-pressed", String(s === this.selected));
      b.button.setAttribute("aria-label", STATE_NAMES[s] + ": P(right) " + percent(pr));
      b.button.classList.toggle("ce-shown", s === shown);
    }

    // ratio track of the shown state
    const eps = ex.settings.epsilon;
    const lowX = this.ratioX(1 - eps);
    const highX = this.ratioX(1 + eps);
    this.band.setAttribute("x", lowX.toFixed(2));
    this.band.setAttribute("width", (highX - lowX).toFixed(2));
    this.band.setAttribute("data-low", fmt(1 - eps, 2));
    this.band.setAttribute("data-high", fmt(1 + eps, 2));
    this.bandLow.setAttribute("x", (lowX - 1).toFixed(2));
    this.bandLow.textContent = fmt(1 - eps, 2);
    this.bandHigh.setAttribute("x", (highX + 1).toFixed(2));
    this.bandHigh.textContent = fmt(1 + eps, 2);
    this.trackTitle.textContent = "ratio r(\u03b8) against the clip band, state " + STATE_NAMES[shown];
    const trackWords = [];
    for (let a = 0; a < 2; a++) {
      const r = rec.ratios[shown][a];
      const adv = rec.advantages[shown][a];
      const clipped = rec.clipped[shown][a];
      const d = this.dots[a];
      const x = this.ratioX(r);
      d.dot.setAttribute("cx", x.toFixed(2));
      d.dot.classList.toggle("ce-clipped", clipped);
      d.dot.classList.toggle("ce-off-scale", r > this.track.rMax);
      d.label.textContent = minus("r " + fmt(r, 2) + "  \u00c2 " + signed(adv, 2));
      trackWords.push(ACTION_NAMES[a] + " ratio " + fmt(r, 2) + (clipped ? ", clipped" : ""));
    }
    this.trackSvg.setAttribute(
      "aria-label",
      "State " + STATE_NAMES[shown] + ": band " + fmt(1 - eps, 2) + " to " + fmt(1 + eps, 2) + "; " + trackWords.join("; ")
    );

    // table of the shown state
    const t = this.table;
    t.caption.textContent = "Inside state " + STATE_NAMES[shown];
    for (let a = 0; a < 2; a++) {
      const cells = t.rows[a];
      cells[0].textContent = percent(rec.probs[shown][a]);
      cells[1].textContent = fmt(rec.ratios[shown][a], 2);
      cells[2].textContent = minus(signed(rec.advantages[shown][a], 3));
      const outside = Math.abs(rec.ratios[shown][a] - 1) > ex.settings.epsilon;
      cells[3].textContent = rec.clipped[shown][a] ? "yes" : outside ? "no (outside band)" : "no";
    }

    this.renderChart();
  };

  CorridorExplorer.prototype.renderChart = function () {
    const c = this.chart;
    const ex = this.explorer;
    const rec = this.record;
    const h = this.history;
    const n = h.length;
    // at most ~500 drawn points: each keeps its bucket's last return and largest KL, so no spike is lost
    const bucket = Math.max(1, Math.ceil(n / 500));
    const points = [];
    for (let i = 0; i < n; i += bucket) {
      let kl = 0;
      for (let j = i; j < Math.min(n, i + bucket); j++) kl = Math.max(kl, h[j].kl);
      points.push({ t: Math.min(n - 1, i + bucket - 1), ret: h[Math.min(n - 1, i + bucket - 1)].ret, kl: kl });
    }
    let klSeen = 0;
    for (const pt of points) klSeen = Math.max(klSeen, pt.kl);
    const limit = rec.kl_limit;
    const klMax = Math.max(2.5 * limit, 1.08 * klSeen);
    const tMax = Math.max(n - 1, 10 * ex.settings.epochs, 40);
    const x = (t) => c.left + ((c.right - c.left) * t) / tMax;
    const yRet = (v) => c.bottom - ((c.bottom - c.top) * (Math.max(-1, Math.min(1, v)) + 1)) / 2;
    const yKl = (v) => c.bottom - ((c.bottom - c.top) * Math.min(v, klMax)) / klMax;
    let ret = "";
    let kl = "";
    for (let i = 0; i < points.length; i++) {
      ret += (i ? "L" : "M") + x(points[i].t).toFixed(1) + " " + yRet(points[i].ret).toFixed(1);
      kl += (i ? "L" : "M") + x(points[i].t).toFixed(1) + " " + yKl(points[i].kl).toFixed(1);
    }
    this.returnLine.setAttribute("d", ret);
    this.klLine.setAttribute("d", kl);
    const lastX = x(points[points.length - 1].t).toFixed(1);
    this.klArea.setAttribute("d", kl + "L" + lastX + " " + c.bottom + "L" + c.left + " " + c.bottom + "Z");
    const setY = (line, y) => {
      line.setAttribute("y1", y.toFixed(1));
      line.setAttribute("y2", y.toFixed(1));
    };
    setY(this.chartZero, yRet(0));
    setY(this.chartOptimal, yRet(ex.optimal));
    setY(this.chartLimit, yKl(limit));
    const T = this.chartText;
    const place = (key, y, text) => {
      T[key].setAttribute("y", (y + 3).toFixed(1));
      T[key].textContent = minus(text);
    };
    place("retTop", yRet(1), "1");
    place("retZero", yRet(0), "0");
    place("retBottom", yRet(-1), "-1");
    place("optimal", yRet(ex.optimal) + 11, "optimal " + fmt(ex.optimal, 3));
    place("klTop", c.top, fmt(klMax, 2));
    place("klZero", c.bottom, "0");
    place("limit", yKl(limit) - 5, "KL limit \u03b5\u00b2 = " + fmt(limit, limit < 0.01 ? 4 : 3));
    T.xEnd.textContent = "round " + ex.round;
  };

  // ---------------------------------------------------------------- start-up

  function loadMath(callback, fail) {
    if (window.CorridorMath) return callback(window.CorridorMath);
    let tag = document.querySelector("script[data-corridor-math]");
    if (!tag) {
      const base = SCRIPT && SCRIPT.src ? SCRIPT.src : document.baseURI;
      tag = document.createElement("script");
      tag.src = new URL("corridor-math.js", base).href;
      tag.setAttribute("data-corridor-math", "");
      document.head.appendChild(tag);
    }
    tag.addEventListener("load", () => callback(window.CorridorMath));
    tag.addEventListener("error", fail);
  }

  function start() {
    const roots = Array.prototype.slice.call(document.querySelectorAll("div.corridor-explorer"));
    if (!roots.length) return;
    loadMath(
      (M) => {
        for (const root of roots) if (!root.hasAttribute("data-ready")) new CorridorExplorer(root, M);
      },
      () => {
        for (const root of roots) root.textContent = "The corridor explorer could not load its math (corridor-math.js).";
      }
    );
  }

  if (document.readyState === "loading") document.addEventListener("DOMContentLoaded", start);
  else start();
})();
