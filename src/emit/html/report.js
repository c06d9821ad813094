"use strict";
// The deviation report's viewer. Data: the JSON document of
// #report-data. Each row is [line, motion, x, y, z, dx, dy, dz, effect
// parts..., residual, orient_urad (, file)]: the line and the end point
// (x, y, z) as differences from the previous row's, positions in units of
// 1/pos_per_mm mm, deviations and parts in 1/dev_per_mm mm, the residual
// in 1/res_per_mm mm (-1: not predicted); the file index only when the
// report has several files. `starts` gives a row's start (absolute) when
// it is not the previous row's end, `arcs` a row's arc as [cx, cy, cz,
// nx, ny, nz, sweep_rad] (centre in position units); `u`, only when the
// machine file carries a parameter covariance, a row's expanded
// uncertainty U (k=2) of |deviation| in deviation units.
(function () {
  var D = JSON.parse(document.getElementById("report-data").textContent);
  var NE = D.effects.length;
  var U = D.units;
  var TAU = 2 * Math.PI;

  function scaled(a, k) {
    return [a[0] / k, a[1] / k, a[2] / k];
  }

  function norm3(a) {
    return Math.sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2]);
  }

  // The moves.
  var pts = [];
  var prevEnd = null;
  var prevDev = null;
  var line0 = 0, end0 = [0, 0, 0];
  for (var i = 0; i < D.rows.length; i++) {
    var r = D.rows[i];
    line0 += r[0];
    end0 = [end0[0] + r[2], end0[1] + r[3], end0[2] + r[4]];
    var end = scaled(end0, U.pos_per_mm);
    var given = D.starts[String(i)];
    var start = given ? scaled(given, U.pos_per_mm) : prevEnd || end;
    var dev = scaled([r[5], r[6], r[7]], U.dev_per_mm);
    var eff = [];
    for (var k = 0; k < NE; k++) {
      eff.push(r[8 + k] / U.dev_per_mm);
    }
    var res = r[8 + NE];
    var a = D.arcs[String(i)];
    var p = {
      i: i,
      line: line0,
      file: r.length > 10 + NE ? r[10 + NE] : 0,
      motion: D.motions[r[1]],
      rapid: D.positioning[r[1]],
      hole: D.holes[r[1]],
      start: start,
      end: end,
      dev: dev,
      devStart: given || !prevDev ? dev : prevDev,
      d: norm3(dev),
      eff: eff,
      res: res < 0 ? null : res / U.res_per_mm,
      orient: r[9 + NE],
      arc: a ? { c: scaled(a, U.pos_per_mm), n: [a[3], a[4], a[5]], w: a[6] } : null,
      src: D.src[i] || "",
      u: D.u && D.u[String(i)] !== undefined ? D.u[String(i)] / U.dev_per_mm : null
    };
    p.plunge =
      !p.rapid && !p.arc && !p.hole &&
      Math.hypot(end[0] - start[0], end[1] - start[1]) < 0.05 &&
      start[2] - end[2] > 0.5;
    p.g = geometry(p);
    pts.push(p);
    prevEnd = end;
    prevDev = dev;
  }

  // Points along a move, with their parameter s in [0, 1].
  function geometry(p) {
    if (p.hole) {
      var over = [p.end[0], p.end[1], p.start[2]];
      return { x: [p.start, over, p.end], s: [0, 0.5, 1] };
    }
    if (!p.arc) {
      return { x: [p.start, p.end], s: [0, 1] };
    }
    var c = p.arc.c, n = p.arc.n, w = p.arc.w;
    var v0 = [p.start[0] - c[0], p.start[1] - c[1], p.start[2] - c[2]];
    var ax0 = v0[0] * n[0] + v0[1] * n[1] + v0[2] * n[2];
    var vp = [v0[0] - ax0 * n[0], v0[1] - ax0 * n[1], v0[2] - ax0 * n[2]];
    var nxv = [n[1] * vp[2] - n[2] * vp[1], n[2] * vp[0] - n[0] * vp[2], n[0] * vp[1] - n[1] * vp[0]];
    var de = [p.end[0] - p.start[0], p.end[1] - p.start[1], p.end[2] - p.start[2]];
    var axial = de[0] * n[0] + de[1] * n[1] + de[2] * n[2];
    var steps = Math.min(360, Math.max(4, Math.ceil(Math.abs(w) / (TAU / 180))));
    var xs = [], ss = [];
    for (var j = 0; j <= steps; j++) {
      var s = j / steps;
      if (j === steps) {
        xs.push(p.end);
      } else {
        var t = w * s, co = Math.cos(t), si = Math.sin(t), h = ax0 + axial * s;
        xs.push([
          c[0] + vp[0] * co + nxv[0] * si + h * n[0],
          c[1] + vp[1] * co + nxv[1] * si + h * n[1],
          c[2] + vp[2] * co + nxv[2] * si + h * n[2]
        ]);
      }
      ss.push(s);
    }
    return { x: xs, s: ss };
  }

  // Colour scale: the cutting moves' range of |deviation|.
  var lo = Infinity, hi = 0, top = 0;
  pts.forEach(function (p) {
    top = Math.max(top, p.d);
    if (!p.rapid) {
      lo = Math.min(lo, p.d);
      hi = Math.max(hi, p.d);
    }
  });
  if (!(hi > 0 && hi - lo > 1e-6)) {
    lo = 0;
    hi = top > 0 ? top : 1e-3;
  }
  document.getElementById("scale-lo").textContent = lo.toFixed(4);
  document.getElementById("scale-hi").textContent = hi.toFixed(4);

  var STOPS = [[68, 1, 84], [59, 82, 139], [33, 145, 140], [94, 201, 98], [253, 231, 37]];
  function colour(d) {
    var t = (d - lo) / (hi - lo);
    if (!isFinite(t)) t = 0;
    t = Math.min(1, Math.max(0, t));
    var x = t * (STOPS.length - 1);
    var k = Math.min(STOPS.length - 2, Math.floor(x));
    var f = x - k, A = STOPS[k], B = STOPS[k + 1];
    return "rgb(" + [0, 1, 2].map(function (m) {
      return Math.round(A[m] + (B[m] - A[m]) * f);
    }).join(",") + ")";
  }

  // Magnification of the predicted path: by default the largest cutting
  // deviation drawn as 4 % of the part's size, rounded to 1, 2 or 5 × 10^k.
  var fitted = pts.some(function (p) { return !p.rapid; })
    ? pts.filter(function (p) { return !p.rapid; })
    : pts;
  var bmin = [Infinity, Infinity, Infinity], bmax = [-Infinity, -Infinity, -Infinity];
  fitted.forEach(function (p) {
    p.g.x.forEach(function (q) {
      for (var m = 0; m < 3; m++) {
        bmin[m] = Math.min(bmin[m], q[m]);
        bmax[m] = Math.max(bmax[m], q[m]);
      }
    });
  });
  var diag = isFinite(bmin[0]) ? norm3([bmax[0] - bmin[0], bmax[1] - bmin[1], bmax[2] - bmin[2]]) : 1;
  function nice(v) {
    if (!(v > 0) || !isFinite(v)) return 1;
    var e = Math.pow(10, Math.floor(Math.log10(v)));
    var f = v / e;
    return (f >= 5 ? 5 : f >= 2 ? 2 : 1) * e;
  }
  var magInput = document.getElementById("mag");
  magInput.value = String(nice(0.04 * Math.max(diag, 1) / (hi > 0 ? hi : 1e-3)));
  function mag() {
    var v = parseFloat(magInput.value);
    return isFinite(v) && v >= 0 ? v : 0;
  }
  var showPredicted = document.getElementById("show-predicted");
  var showRapids = document.getElementById("show-rapids");

  function devAt(p, s) {
    var a = p.devStart, b = p.dev;
    return [a[0] + (b[0] - a[0]) * s, a[1] + (b[1] - a[1]) * s, a[2] + (b[2] - a[2]) * s];
  }

  // One view: a projection of the toolpath onto a canvas.
  function View(id, kind) {
    this.cv = document.getElementById(id);
    this.ctx = this.cv.getContext("2d");
    this.kind = kind;
    this.az = 0.55;
    this.el = 0.6;
    this.reset();
  }
  View.prototype.reset = function () {
    this.zoom = 1;
    this.pan = [0, 0];
    if (this.kind === "iso") {
      this.az = 0.55;
      this.el = 0.6;
    }
    this.fit();
  };
  View.prototype.proj = function (q) {
    if (this.kind === "plan") return [q[0], q[1]];
    if (this.kind === "side") return [q[0], q[2]];
    var ca = Math.cos(this.az), sa = Math.sin(this.az);
    var ce = Math.cos(this.el), se = Math.sin(this.el);
    var xr = q[0] * ca - q[1] * sa, yr = q[0] * sa + q[1] * ca;
    return [xr, yr * se + q[2] * ce];
  };
  View.prototype.fit = function () {
    var W = this.cv.clientWidth || this.cv.width, H = this.cv.clientHeight || this.cv.height;
    var u0 = Infinity, u1 = -Infinity, v0 = Infinity, v1 = -Infinity, self = this;
    fitted.forEach(function (p) {
      p.g.x.forEach(function (q) {
        var uv = self.proj(q);
        u0 = Math.min(u0, uv[0]);
        u1 = Math.max(u1, uv[0]);
        v0 = Math.min(v0, uv[1]);
        v1 = Math.max(v1, uv[1]);
      });
    });
    if (!isFinite(u0)) {
      u0 = 0; u1 = 1; v0 = 0; v1 = 1;
    }
    this.c = [(u0 + u1) / 2, (v0 + v1) / 2];
    this.s = Math.min((W - 50) / Math.max(u1 - u0, 1), (H - 50) / Math.max(v1 - v0, 1));
    this.W = W;
    this.H = H;
  };
  View.prototype.px = function (q) {
    var uv = this.proj(q), s = this.s * this.zoom;
    return [this.W / 2 + this.pan[0] + (uv[0] - this.c[0]) * s, this.H / 2 + this.pan[1] - (uv[1] - this.c[1]) * s];
  };
  View.prototype.predicted = function (p, j) {
    var q = p.g.x[j], dv = devAt(p, p.g.s[j]), m = mag();
    return [q[0] + m * dv[0], q[1] + m * dv[1], q[2] + m * dv[2]];
  };
  View.prototype.stroke = function (p, style, width, dash, predicted) {
    var ctx = this.ctx, n = p.g.x.length;
    ctx.beginPath();
    for (var j = 0; j < n; j++) {
      var xy = this.px(predicted ? this.predicted(p, j) : p.g.x[j]);
      if (j === 0) ctx.moveTo(xy[0], xy[1]);
      else ctx.lineTo(xy[0], xy[1]);
    }
    ctx.strokeStyle = style;
    ctx.lineWidth = width;
    ctx.setLineDash(dash);
    ctx.stroke();
  };
  View.prototype.ring = function (q, r, style, width, fill) {
    var xy = this.px(q), ctx = this.ctx;
    if (xy[0] < -r || xy[1] < -r || xy[0] > this.W + r || xy[1] > this.H + r) return false;
    ctx.beginPath();
    ctx.arc(xy[0], xy[1], r, 0, TAU);
    ctx.setLineDash([]);
    if (fill) {
      ctx.fillStyle = fill;
      ctx.fill();
    }
    ctx.strokeStyle = style;
    ctx.lineWidth = width;
    ctx.stroke();
    return true;
  };
  View.prototype.scaleBar = function () {
    var s = this.s * this.zoom, len = nice(100 / s), ctx = this.ctx;
    var x = 14, y = this.H - 14;
    ctx.setLineDash([]);
    ctx.strokeStyle = "#333";
    ctx.lineWidth = 1.5;
    ctx.beginPath();
    ctx.moveTo(x, y - 4);
    ctx.lineTo(x, y);
    ctx.lineTo(x + len * s, y);
    ctx.lineTo(x + len * s, y - 4);
    ctx.stroke();
    ctx.fillStyle = "#333";
    ctx.font = "12px sans-serif";
    ctx.fillText(len + " mm", x + 4, y - 6);
    var names = this.kind === "plan" ? ["X", "Y"] : this.kind === "side" ? ["X", "Z"] : null;
    if (names) {
      ctx.fillText(names[0] + " \u2192", this.W - 40, this.H - 10);
      ctx.fillText(names[1] + " \u2191", 10, 16);
    } else {
      var o = [this.W - 50, this.H - 30], self = this;
      ["X", "Y", "Z"].forEach(function (name, m) {
        var e = [0, 0, 0];
        e[m] = 1;
        var a = self.proj(e), b = self.proj([0, 0, 0]);
        var dx = (a[0] - b[0]) * 22, dy = -(a[1] - b[1]) * 22;
        ctx.beginPath();
        ctx.moveTo(o[0], o[1]);
        ctx.lineTo(o[0] + dx, o[1] + dy);
        ctx.stroke();
        ctx.fillText(name, o[0] + dx * 1.25 - 3, o[1] + dy * 1.25 + 4);
      });
    }
  };
  View.prototype.draw = function () {
    var ctx = this.ctx, dpr = window.devicePixelRatio || 1, self = this;
    if (this.cv.width !== Math.round(this.W * dpr)) {
      this.cv.width = Math.round(this.W * dpr);
      this.cv.height = Math.round(this.H * dpr);
    }
    ctx.setTransform(dpr, 0, 0, dpr, 0, 0);
    ctx.fillStyle = "#ffffff";
    ctx.fillRect(0, 0, this.W, this.H);
    ctx.lineCap = "round";
    ctx.lineJoin = "round";
    var drawn = 0;
    pts.forEach(function (p) {
      if (p.rapid && showRapids.checked) {
        self.stroke(p, "#8a96a3", 1, [4, 3], false);
      }
    });
    pts.forEach(function (p) {
      if (!p.rapid) {
        self.stroke(p, colour(p.d), 2.5, [], false);
        drawn++;
      }
    });
    if (showPredicted.checked && mag() > 0) {
      pts.forEach(function (p) {
        if (!p.rapid) {
          self.stroke(p, "#c2185b", 1.2, [], true);
        }
      });
    }
    if (this.kind === "plan") {
      pts.forEach(function (p) {
        if (p.hole || p.plunge) {
          self.ring(p.end, 5, "#222", 1.5, colour(p.d));
        }
      });
    }
    var shown = selected !== null ? selected : hovered;
    if (shown !== null) {
      var p = pts[shown];
      this.stroke(p, "#000", 4.5, [], false);
      this.ring(p.end, 6, "#000", 2, null);
    }
    D.marks.forEach(function (m) {
      if (self.ring(m.pos, 9, m.cut ? "#ff8c00" : "#ff0000", 3, null)) {
        var xy = self.px(m.pos);
        var label = (m.cut ? "max cutting " : "max ") + m.dev.toFixed(4) + " mm" +
          (m.u !== undefined ? " (U " + m.u.toFixed(4) + ")" : "") + ", " +
          (D.files.length > 1 ? D.files[m.file] + ":" : "line ") + m.line;
        ctx.fillStyle = "#222";
        ctx.font = "12px sans-serif";
        var w = ctx.measureText(label).width;
        var x = xy[0] + 13 + w > self.W - 4 ? xy[0] - 13 - w : xy[0] + 13;
        ctx.fillText(label, x, xy[1] - 11);
      }
    });
    this.scaleBar();
    var rect = this.cv.getBoundingClientRect();
    var ds = this.cv.dataset;
    ds.cu = String(this.c[0]);
    ds.cv = String(this.c[1]);
    ds.scale = String(this.s * this.zoom);
    ds.panX = String(this.pan[0]);
    ds.panY = String(this.pan[1]);
    ds.left = String(rect.left + window.scrollX + this.cv.clientLeft);
    ds.top = String(rect.top + window.scrollY + this.cv.clientTop);
    ds.width = String(this.W);
    ds.height = String(this.H);
    ds.drawn = String(drawn);
  };
  View.prototype.nearest = function (x, y) {
    var best = null, bd = 100;
    for (var i = 0; i < pts.length; i++) {
      var p = pts[i];
      if (p.rapid && !showRapids.checked) continue;
      var g = p.g.x, step = Math.max(1, Math.floor(g.length / 8));
      for (var j = g.length - 1; j >= 0; j -= step) {
        var xy = this.px(g[j]);
        var d = (xy[0] - x) * (xy[0] - x) + (xy[1] - y) * (xy[1] - y);
        if (d < bd) {
          bd = d;
          best = i;
        }
      }
    }
    return best;
  };

  var hovered = null, selected = null;
  var views = [new View("plan", "plan"), new View("side", "side"), new View("iso", "iso")];
  var pending = false;
  function redraw() {
    if (pending) return;
    pending = true;
    window.requestAnimationFrame(function () {
      pending = false;
      views.forEach(function (v) { v.draw(); });
    });
  }

  function esc(s) {
    return String(s).replace(/[&<>"']/g, function (c) {
      return { "&": "&amp;", "<": "&lt;", ">": "&gt;", "\"": "&quot;", "'": "&#39;" }[c];
    });
  }
  function f(v, d) {
    return isFinite(v) ? v.toFixed(d) : "nan";
  }
  function info(i, note) {
    var el = document.getElementById("info");
    if (i === null) {
      if (note) el.innerHTML = "<p>" + esc(note) + "</p>";
      return;
    }
    var p = pts[i];
    var where = D.files.length > 1 ? D.files[p.file] + ":" + p.line : "line " + p.line;
    var h = "<p><b>" + esc(where) + "</b> &mdash; " + esc(p.motion) + (selected === i ? " (kept; click elsewhere to let go)" : "") + "</p>";
    h += "<p><code>" + esc(p.src) + "</code></p>";
    h += "<table><tbody>";
    h += "<tr><td>programmed end (mm)</td><td>" + p.end.map(function (v) { return f(v, 3); }).join(", ") + "</td></tr>";
    h += "<tr><td>|deviation| (mm)</td><td><b>" + f(p.d, 5) + "</b></td></tr>";
    if (p.u !== null) h += "<tr><td>U (k=2) of |deviation| (mm)</td><td>" + f(p.u, 5) + "</td></tr>";
    h += "<tr><td>dx, dy, dz (mm)</td><td>" + p.dev.map(function (v) { return f(v, 5); }).join(", ") + "</td></tr>";
    for (var k = 0; k < NE; k++) {
      h += "<tr><td>" + esc(D.effects[k]) + " part (mm)</td><td>" + f(p.eff[k], 5) + "</td></tr>";
    }
    h += "<tr><td>residual after compensation (mm)</td><td>" + (p.res === null ? "not predicted for robot programs" : f(p.res, 6)) + "</td></tr>";
    h += "<tr><td>tool-axis error (&micro;rad)</td><td>" + f(p.orient, 0) + "</td></tr>";
    h += "</tbody></table>";
    if (p.hole) h += "<p>drilling cycle: hole bottom shown</p>";
    el.innerHTML = h;
  }

  views.forEach(function (v) {
    var drag = null;
    v.cv.addEventListener("mousemove", function (e) {
      var r = v.cv.getBoundingClientRect(), x = e.clientX - r.left, y = e.clientY - r.top;
      if (drag) {
        var dx = x - drag[0], dy = y - drag[1];
        if (Math.abs(dx) + Math.abs(dy) > 2) drag[2] = true;
        if (v.kind === "iso") {
          v.az += dx * 0.01;
          v.el = Math.max(-Math.PI / 2, Math.min(Math.PI / 2, v.el + dy * 0.01));
          v.fit();
        } else {
          v.pan = [v.pan[0] + dx, v.pan[1] + dy];
        }
        drag[0] = x;
        drag[1] = y;
        redraw();
        return;
      }
      var i = v.nearest(x, y);
      if (i !== hovered) {
        hovered = i;
        if (selected === null) info(i);
        redraw();
      }
    });
    v.cv.addEventListener("mousedown", function (e) {
      var r = v.cv.getBoundingClientRect();
      drag = [e.clientX - r.left, e.clientY - r.top, false];
    });
    window.addEventListener("mouseup", function () {
      if (drag && !drag[2]) {
        selected = hovered;
        info(selected);
        redraw();
      }
      drag = null;
    });
    v.cv.addEventListener("wheel", function (e) {
      e.preventDefault();
      var r = v.cv.getBoundingClientRect(), x = e.clientX - r.left, y = e.clientY - r.top;
      var k = e.deltaY < 0 ? 1.25 : 0.8;
      var ox = x - v.W / 2 - v.pan[0], oy = y - v.H / 2 - v.pan[1];
      v.pan = [x - v.W / 2 - ox * k, y - v.H / 2 - oy * k];
      v.zoom *= k;
      redraw();
    }, { passive: false });
  });
  document.getElementById("reset").addEventListener("click", function () {
    views.forEach(function (v) { v.reset(); });
    redraw();
  });
  [magInput, showPredicted, showRapids].forEach(function (el) {
    el.addEventListener("input", redraw);
    el.addEventListener("change", redraw);
  });
  Array.prototype.forEach.call(document.querySelectorAll("a.block"), function (a) {
    a.addEventListener("click", function (e) {
      e.preventDefault();
      var file = Number(a.getAttribute("data-file")), line = Number(a.getAttribute("data-line"));
      var found = null;
      for (var i = 0; i < pts.length; i++) {
        if (pts[i].file === file && pts[i].line === line) found = i;
      }
      selected = found;
      if (found === null) info(null, "Line " + line + " is not among the drawn points (the program is thinned).");
      else info(found);
      redraw();
    });
  });
  views.forEach(function (v) { v.draw(); });
  document.body.setAttribute("data-drawn", String(pts.length));
})();
