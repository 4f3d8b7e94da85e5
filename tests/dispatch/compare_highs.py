#!/usr/bin/env python3
"""Optimality check of `gridscada dispatch solve` against HiGHS.

Generates random single-period and multi-period (horizon) dispatch problems
with a fixed seed, solves them with the gridscada binary (one batch call: the
CLI accepts a JSON list of problems) and with HiGHS (`pip install highspy`),
formulated here independently from the documented semantics
(docs/DISPATCH.md). Checks, for every instance:

- both agree on feasibility;
- objectives agree within 1e-6 relative (|a-b| <= 1e-6 * max(1, |b|));
- the returned setpoints satisfy every constraint within 1e-6 (kW / kWh);
- the returned objective equals the cost recomputed from the setpoints.

Usage: compare_highs.py [BIN] [--single N] [--multi M] [--seed S]
BIN defaults to $GRIDSCADA_BIN. BIN is called as `BIN dispatch solve -`
(the control crate's `dispatch_solve` example accepts the same arguments).
Prints "N passed, M failed" and exits non-zero on any failure.
"""

import argparse
import json
import os
import random
import statistics
import subprocess
import sys
import time

import highspy
import numpy as np

TOL = 1e-6
INF = highspy.kHighsInf


def rel_ok(a, b):
    return abs(a - b) <= TOL * max(1.0, abs(b))


# ---------------------------------------------------------------- generators


def gen_single(rng, i):
    dt = rng.choice([5 / 3600, 0.25, 1.0, 2.0])
    ids = iter(f"u{k}" for k in range(100))
    def ren():
        return {"id": next(ids), "available_kw": round(rng.uniform(0, 120), 3),
                "cost_per_kwh": rng.choice([0.0, 0.0, round(rng.uniform(0, 0.05), 4)])}
    pv = [ren() for _ in range(rng.randint(0, 3))]
    wind = [ren() for _ in range(rng.randint(0, 2))]
    oil = []
    for _ in range(rng.randint(0, 2)):
        mn = round(rng.uniform(0, 50), 3)
        oil.append({"id": next(ids), "running": rng.random() < 0.7, "min_kw": mn,
                    "max_kw": round(mn + rng.uniform(0, 150), 3),
                    "cost_per_kwh": round(rng.uniform(0.2, 0.6), 4)})
    storage = []
    for _ in range(rng.randint(0, 2)):
        smin = round(rng.uniform(0, 40), 3)
        smax = round(smin + rng.uniform(0, 300), 3)
        soc = rng.choice([smin, smax, round(rng.uniform(smin, smax), 3)])
        storage.append({"id": next(ids), "soc_kwh": soc, "soc_min_kwh": smin, "soc_max_kwh": smax,
                        "max_charge_kw": round(rng.uniform(0, 80), 3),
                        "max_discharge_kw": round(rng.uniform(0, 80), 3),
                        "eff_charge": round(rng.uniform(0.8, 1.0), 4),
                        "eff_discharge": round(rng.uniform(0.8, 1.0), 4),
                        "cycle_cost_per_kwh": round(rng.uniform(0, 0.05), 4)})
    demand = 0.0 if i % 37 == 0 else round(rng.uniform(0, 400), 3)
    return {"dt_h": dt, "demand_kw": demand, "voll_per_kwh": rng.choice([1.0, 5.0, 10.0]),
            "pv": pv, "wind": wind, "oil": oil, "storage": storage}


def gen_multi(rng, i):
    nt = rng.choice([4, 12, 24, 48])
    dt = 24.0 / nt
    ids = iter(f"u{k}" for k in range(100))
    def ren():
        u = {"id": next(ids), "cost_per_kwh": round(rng.uniform(0, 0.03), 4)}
        if rng.random() < 0.5:
            u["ramp_kw_per_s"] = round(rng.uniform(0.001, 0.02), 4)
            u["initial_kw"] = round(rng.uniform(0, 50), 3)
        return u
    pv = [ren() for _ in range(rng.randint(1, 2))]
    wind = [ren() for _ in range(rng.randint(0, 1))]
    oil = []
    for _ in range(rng.randint(0, 2)):
        mn = round(rng.uniform(0, 30), 3)
        mx = round(mn + rng.uniform(50, 150), 3)
        u = {"id": next(ids), "running": rng.random() < 0.8, "min_kw": mn, "max_kw": mx,
             "cost_per_kwh": round(rng.uniform(0.2, 0.6), 4)}
        if rng.random() < 0.5:
            u["ramp_kw_per_s"] = round(rng.uniform(0.005, 0.03), 4)
            u["initial_kw"] = round(rng.uniform(mn, mx), 3)
        oil.append(u)
    storage = []
    for _ in range(rng.randint(0, 2)):
        smin = round(rng.uniform(0, 40), 3)
        smax = round(smin + rng.uniform(50, 300), 3)
        u = {"id": next(ids), "soc_kwh": round(rng.uniform(smin, smax), 3), "soc_min_kwh": smin,
             "soc_max_kwh": smax, "max_charge_kw": round(rng.uniform(10, 80), 3),
             "max_discharge_kw": round(rng.uniform(10, 80), 3),
             "eff_charge": round(rng.uniform(0.85, 1.0), 4),
             "eff_discharge": round(rng.uniform(0.85, 1.0), 4),
             "cycle_cost_per_kwh": round(rng.uniform(0, 0.04), 4),
             "terminal_value_per_kwh": round(rng.uniform(0, 0.3), 4)}
        if rng.random() < 0.5:
            u["ramp_kw_per_s"] = round(rng.uniform(0.005, 0.03), 4)
            u["initial_kw"] = round(rng.uniform(-u["max_charge_kw"], u["max_discharge_kw"]), 3)
        storage.append(u)
    periods = []
    for t in range(nt):
        per = {"demand_kw": round(rng.uniform(20, 250), 3),
               "available_kw": {u["id"]: round(rng.uniform(0, 120), 3) for u in pv + wind}}
        if oil and rng.random() < 0.2:
            per["running"] = {oil[0]["id"]: rng.random() < 0.5}
        periods.append(per)
    p = {"dt_h": dt, "voll_per_kwh": rng.choice([2.0, 5.0]), "periods": periods,
         "pv": pv, "wind": wind, "oil": oil, "storage": storage}
    if rng.random() < 0.6:
        p["reserve"] = {"load_frac": round(rng.uniform(0, 0.2), 3), "pv_frac": round(rng.uniform(0, 0.3), 3),
                        "wind_frac": round(rng.uniform(0, 0.3), 3),
                        "shortfall_cost_per_kwh": round(rng.uniform(0.1, 2.0), 3)}
    if rng.random() < 0.3:
        p["max_renewable_share"] = round(rng.uniform(0.2, 0.9), 3)
    if i % 4 == 0:
        p["smoothing_cost_per_kw2"] = round(rng.uniform(1e-4, 1e-2), 5)
    return p


def gen_commit(rng, i):
    """A horizon whose diesels' on/off the problem decides (optimize_commitment):
    a night or a cloudy morning, 8-16 periods, one or two diesels priced by a
    fuel curve (no-load cost per hour, start cost, minimum up and down times,
    the time already spent in the present state), one battery."""
    nt = rng.choice([8, 12, 16])
    dt = rng.choice([0.25, 0.5])
    ids = iter(f"c{k}" for k in range(100))
    pv = [{"id": next(ids), "cost_per_kwh": round(rng.uniform(0, 0.02), 4)}]
    oil = []
    for _ in range(rng.randint(1, 2)):
        mx = round(rng.uniform(50, 160), 3)
        mn = round(mx * rng.uniform(0.2, 0.4), 3)
        running = rng.random() < 0.5
        oil.append({"id": next(ids), "running": running, "min_kw": mn, "max_kw": mx,
                    "cost_per_kwh": round(rng.uniform(0.3, 0.45), 4),
                    "optimize_commitment": True,
                    "no_load_cost_per_h": round(mx * rng.uniform(0.08, 0.15), 3),
                    "start_cost": round(rng.choice([0.0, rng.uniform(0.5, 5.0)]), 3),
                    "min_up_h": rng.choice([0.0, 0.25, 0.5, 1.0]),
                    "min_down_h": rng.choice([0.0, 0.25, 0.5]),
                    "hours_in_state": rng.choice([0.1, 0.3, 5.0])})
    smin = 20.0
    storage = [{"id": next(ids), "soc_kwh": round(rng.uniform(25, 180), 3), "soc_min_kwh": smin,
                "soc_max_kwh": 190.0, "max_charge_kw": 50.0, "max_discharge_kw": 60.0,
                "eff_charge": 0.95, "eff_discharge": 0.95,
                "cycle_cost_per_kwh": round(rng.uniform(0, 0.03), 4),
                "terminal_value_per_kwh": round(rng.uniform(0, 0.45), 4)}]
    base = rng.uniform(40, 110)
    periods = [{"demand_kw": round(base * rng.uniform(0.8, 1.2), 3),
                "available_kw": {pv[0]["id"]: round(max(0.0, rng.uniform(-40, 60)), 3)}}
               for _ in range(nt)]
    p = {"dt_h": dt, "voll_per_kwh": 5.0, "periods": periods, "pv": pv, "wind": [],
         "oil": oil, "storage": storage}
    if rng.random() < 0.4:
        p["reserve"] = {"load_frac": 0.1, "pv_frac": 0.2, "wind_frac": 0.0,
                        "shortfall_cost_per_kwh": round(rng.uniform(0.1, 1.0), 3)}
    return p


# ------------------------------------------------------- independent models


class Lp:
    """Tiny builder over highspy: variables, rows, linear + quadratic cost."""

    def __init__(self):
        self.lb, self.ub, self.c, self.rows, self.q, self.const = [], [], [], [], {}, 0.0
        self.integer = []

    def var(self, lb, ub, c=0.0):
        self.lb.append(lb); self.ub.append(ub); self.c.append(c)
        return len(self.lb) - 1

    def row(self, lo, hi, coefs):
        self.rows.append((lo, hi, coefs))

    def square(self, w, coefs, k):
        """add w * (sum a x - k)^2"""
        for i, a in coefs:
            for j, b in coefs:
                self.q[(i, j)] = self.q.get((i, j), 0.0) + 2 * w * a * b
            self.c[i] -= 2 * w * k * a
        self.const += w * k * k

    def solve(self):
        h = highspy.Highs()
        h.setOptionValue("output_flag", False)
        n = len(self.lb)
        h.addVars(n, np.array(self.lb), np.array(self.ub))
        h.changeColsCost(n, np.arange(n, dtype=np.int32), np.array(self.c, dtype=float))
        for lo, hi, coefs in self.rows:
            idx = np.array([i for i, _ in coefs], dtype=np.int32)
            val = np.array([a for _, a in coefs], dtype=float)
            h.addRow(lo, hi, len(coefs), idx, val)
        if self.integer:
            h.changeColsIntegrality(len(self.integer), np.array(self.integer, dtype=np.int32),
                                    np.array([highspy.HighsVarType.kInteger] * len(self.integer)))
            h.setOptionValue("mip_rel_gap", 1e-7)
        if self.q:
            # Lower triangle, column-wise.
            start, index, value = [], [], []
            for col in range(n):
                start.append(len(index))
                for row in range(col, n):
                    v = self.q.get((row, col), 0.0)
                    if v != 0.0:
                        index.append(row); value.append(v)
            h.passHessian(n, len(index), highspy.HessianFormat.kTriangular,
                          np.array(start, dtype=np.int32), np.array(index, dtype=np.int32),
                          np.array(value, dtype=float))
        t0 = time.perf_counter()
        h.run()
        ms = (time.perf_counter() - t0) * 1e3
        st = h.getModelStatus()
        if st == highspy.HighsModelStatus.kOptimal:
            return "optimal", h.getInfo().objective_function_value + self.const, ms
        if st == highspy.HighsModelStatus.kInfeasible:
            return "infeasible", None, ms
        return f"highs:{h.modelStatusToString(st)}", None, ms


def highs_single(p):
    m, dt, bal = Lp(), p["dt_h"], []
    for u in p["pv"] + p["wind"]:
        bal.append((m.var(0, u["available_kw"], dt * u["cost_per_kwh"]), 1.0))
    for u in p["oil"]:
        lo, hi = (u["min_kw"], u["max_kw"]) if u["running"] else (0, 0)
        bal.append((m.var(lo, hi, dt * u["cost_per_kwh"]), 1.0))
    for s in p["storage"]:
        c = dt * s["cycle_cost_per_kwh"]
        ch = m.var(0, s["max_charge_kw"], c)
        dis = m.var(0, s["max_discharge_kw"], c)
        m.row(-INF, s["soc_max_kwh"] - s["soc_kwh"], [(ch, s["eff_charge"] * dt)])
        m.row(-INF, s["soc_kwh"] - s["soc_min_kwh"], [(dis, dt / s["eff_discharge"])])
        bal += [(ch, -1.0), (dis, 1.0)]
    bal.append((m.var(0, p["demand_kw"], dt * p["voll_per_kwh"]), 1.0))
    m.row(p["demand_kw"], p["demand_kw"], bal)
    return m.solve()


def running(p, t, u):
    return p["periods"][t].get("running", {}).get(u["id"], u["running"])


def highs_multi(p):
    m, dt, nt = Lp(), p["dt_h"], len(p["periods"])
    w = p.get("smoothing_cost_per_kw2", 0.0)
    rz = p.get("reserve")
    R = lambda u: u.get("ramp_kw_per_s", 0) * 3600 * dt
    prev = {}
    for t, per in enumerate(p["periods"]):
        bal, ren, oil_run, heads = [], [], [], []
        for kind in ("pv", "wind"):
            for u in p[kind]:
                j = m.var(0, per["available_kw"][u["id"]], dt * u["cost_per_kwh"])
                bal.append((j, 1.0)); ren.append((j, kind))
                pj = prev.get(u["id"])
                if R(u) > 0:
                    if pj is not None:
                        m.row(-INF, R(u), [(j, 1), (pj, -1)])
                    elif "initial_kw" in u:
                        m.row(-INF, u["initial_kw"] + R(u), [(j, 1)])
                if w > 0:
                    if pj is not None:
                        m.square(w, [(j, 1), (pj, -1)], 0)
                    elif "initial_kw" in u:
                        m.square(w, [(j, 1)], u["initial_kw"])
                prev[u["id"]] = j
        for u in p["oil"]:
            run = running(p, t, u)
            lo, hi = (u["min_kw"], u["max_kw"]) if run else (0, 0)
            j = m.var(lo, hi, dt * u["cost_per_kwh"])
            bal.append((j, 1.0))
            if run:
                oil_run.append((j, u["max_kw"]))
            pj = prev.get(u["id"])
            was = running(p, t - 1, u) if t > 0 else ("initial_kw" in u)
            if R(u) > 0 and run and was:
                if pj is not None:
                    m.row(-R(u), R(u), [(j, 1), (pj, -1)])
                else:
                    m.row(u["initial_kw"] - R(u), u["initial_kw"] + R(u), [(j, 1)])
            if w > 0:
                if pj is not None:
                    m.square(w, [(j, 1), (pj, -1)], 0)
                elif "initial_kw" in u:
                    m.square(w, [(j, 1)], u["initial_kw"])
            prev[u["id"]] = j
        for s in p["storage"]:
            c = dt * s["cycle_cost_per_kwh"]
            ch = m.var(0, s["max_charge_kw"], c)
            dis = m.var(0, s["max_discharge_kw"], c)
            soc = m.var(s["soc_min_kwh"], s["soc_max_kwh"],
                        -s.get("terminal_value_per_kwh", 0) if t == nt - 1 else 0)
            bal += [(ch, -1.0), (dis, 1.0)]
            ps = prev.get(s["id"])
            dyn = [(soc, 1), (ch, -s["eff_charge"] * dt), (dis, dt / s["eff_discharge"])]
            if ps is None:
                m.row(s["soc_kwh"], s["soc_kwh"], dyn)
            else:
                m.row(0, 0, dyn + [(ps[2], -1)])
            net = [(dis, 1), (ch, -1)]
            if R(s) > 0:
                if ps is not None:
                    m.row(-R(s), R(s), net + [(ps[1], -1), (ps[0], 1)])
                elif "initial_kw" in s:
                    m.row(s["initial_kw"] - R(s), s["initial_kw"] + R(s), net)
            if w > 0:
                if ps is not None:
                    m.square(w, net + [(ps[1], -1), (ps[0], 1)], 0)
                elif "initial_kw" in s:
                    m.square(w, net, s["initial_kw"])
            if rz:
                hv = m.var(0, INF)
                g = s["eff_discharge"] / dt
                m.row(-INF, s["max_discharge_kw"], [(hv, 1)] + net)
                if ps is None:
                    m.row(-INF, (s["soc_kwh"] - s["soc_min_kwh"]) * g, [(hv, 1)] + net)
                else:
                    m.row(-INF, -s["soc_min_kwh"] * g, [(hv, 1)] + net + [(ps[2], -g)])
                heads.append(hv)
            prev[s["id"]] = (ch, dis, soc)
        bal.append((m.var(0, per["demand_kw"], dt * p["voll_per_kwh"]), 1.0))
        m.row(per["demand_kw"], per["demand_kw"], bal)
        if rz:
            sf = m.var(0, INF, dt * rz["shortfall_cost_per_kwh"])
            frac = {"pv": rz.get("pv_frac", 0), "wind": rz.get("wind_frac", 0)}
            # sum(max - p_oil) + sum h + sf >= load_frac D + sum frac p
            coefs = [(j, -1) for j, _ in oil_run] + [(h, 1) for h in heads] + [(sf, 1)]
            coefs += [(j, -frac[k]) for j, k in ren]
            m.row(rz.get("load_frac", 0) * per["demand_kw"] - sum(mx for _, mx in oil_run), INF, coefs)
        if "max_renewable_share" in p:
            m.row(-INF, p["max_renewable_share"] * per["demand_kw"], [(j, 1) for j, _ in ren])
    return m.solve()


def highs_commit(p):
    """The commitment problem as a MILP, from docs/DISPATCH.md's semantics:
    on_t binary, start_t - stop_t = on_t - on_(t-1) (on_-1 = running),
    min_kw on_t <= p_t <= max_kw on_t, a start within the last ceil(min_up/dt)
    periods keeps it on, a stop within the last ceil(min_down/dt) keeps it
    off, the first periods forced while the present state's minimum time
    runs; cost dt (cost_per_kwh p + no_load on) + start_cost start."""
    import math
    m, dt, nt = Lp(), p["dt_h"], len(p["periods"])
    rz = p.get("reserve")
    span = lambda h: max(1, math.ceil(h / dt - 1e-9))
    hist = {u["id"]: [] for u in p["oil"]}
    soc_prev = {}
    for t, per in enumerate(p["periods"]):
        bal, ren, heads, oil_terms, oil_cap = [], [], [], [], 0.0
        for kind in ("pv", "wind"):
            for u in p.get(kind, []):
                j = m.var(0, per["available_kw"][u["id"]], dt * u["cost_per_kwh"])
                bal.append((j, 1.0)); ren.append((j, kind))
        for u in p["oil"]:
            j = m.var(0, u["max_kw"], dt * u["cost_per_kwh"])
            left = 0.0
            if u.get("hours_in_state") is not None:
                need = u["min_up_h"] if u["running"] else u["min_down_h"]
                left = max(0.0, need - u["hours_in_state"])
            forced = math.ceil(left / dt - 1e-9 / dt) if left > 0 else 0
            if t < forced:
                v = 1.0 if u["running"] else 0.0
                on = m.var(v, v, dt * u["no_load_cost_per_h"])
            else:
                on = m.var(0, 1, dt * u["no_load_cost_per_h"])
            m.integer.append(on)
            st = m.var(0, 1, u["start_cost"])
            sp = m.var(0, 1, 0.0)
            m.row(-INF, 0, [(j, 1), (on, -u["max_kw"])])
            m.row(-INF, 0, [(j, -1), (on, u["min_kw"])])
            h = hist[u["id"]]
            if h:
                m.row(0, 0, [(on, 1), (h[-1][0], -1), (st, -1), (sp, 1)])
            else:
                r0 = 1.0 if u["running"] else 0.0
                m.row(r0, r0, [(on, 1), (st, -1), (sp, 1)])
            h.append((on, st, sp))
            if u["min_up_h"] > 0:
                win = h[max(0, len(h) - span(u["min_up_h"])):]
                m.row(-INF, 0, [(x[1], 1) for x in win] + [(on, -1)])
            if u["min_down_h"] > 0:
                win = h[max(0, len(h) - span(u["min_down_h"])):]
                m.row(-INF, 1, [(x[2], 1) for x in win] + [(on, 1)])
            bal.append((j, 1.0))
            oil_terms.append((j, on, u["max_kw"]))
        for s_ in p["storage"]:
            c = dt * s_["cycle_cost_per_kwh"]
            ch = m.var(0, s_["max_charge_kw"], c)
            dis = m.var(0, s_["max_discharge_kw"], c)
            floor = s_["soc_min_kwh"]
            if t == nt - 1 and s_.get("final_soc_min_kwh") is not None:
                floor = min(max(floor, s_["final_soc_min_kwh"]), s_["soc_max_kwh"])
            soc = m.var(floor, s_["soc_max_kwh"],
                        -s_.get("terminal_value_per_kwh", 0) if t == nt - 1 else 0)
            bal += [(ch, -1.0), (dis, 1.0)]
            dyn = [(soc, 1), (ch, -s_["eff_charge"] * dt), (dis, dt / s_["eff_discharge"])]
            ps = soc_prev.get(s_["id"])
            if ps is None:
                m.row(s_["soc_kwh"], s_["soc_kwh"], dyn)
            else:
                m.row(0, 0, dyn + [(ps, -1)])
            if rz:
                hv = m.var(0, INF)
                g = s_["eff_discharge"] / dt
                net = [(dis, 1), (ch, -1)]
                m.row(-INF, s_["max_discharge_kw"], [(hv, 1)] + net)
                if ps is None:
                    m.row(-INF, (s_["soc_kwh"] - s_["soc_min_kwh"]) * g, [(hv, 1)] + net)
                else:
                    m.row(-INF, -s_["soc_min_kwh"] * g, [(hv, 1)] + net + [(ps, -g)])
                heads.append(hv)
            soc_prev[s_["id"]] = soc
        bal.append((m.var(0, per["demand_kw"], dt * p["voll_per_kwh"]), 1.0))
        m.row(per["demand_kw"], per["demand_kw"], bal)
        if rz:
            sf = m.var(0, INF, dt * rz["shortfall_cost_per_kwh"])
            # sum(max on - p_oil) + sum h + sf >= load_frac D + pv_frac p_pv
            coefs = [(j, -1) for j, _, _ in oil_terms] + [(on, mx) for _, on, mx in oil_terms]
            coefs += [(hh, 1) for hh in heads] + [(sf, 1)]
            coefs += [(j, -rz.get(f"{k}_frac", 0)) for j, k in ren]
            m.row(rz.get("load_frac", 0) * per["demand_kw"], INF, coefs)
    return m.solve()


# -------------------------------------------------- checks of our answers


def check_single(p, s):
    """Every constraint within TOL; returns (errors, recomputed objective)."""
    err, dt, sp = [], p["dt_h"], s["setpoints_kw"]
    cost, total = 0.0, 0.0
    def need(cond, msg):
        if not cond:
            err.append(msg)
    for u in p["pv"] + p["wind"]:
        v = sp[u["id"]]; total += v; cost += dt * u["cost_per_kwh"] * v
        need(-TOL <= v <= u["available_kw"] + TOL, f"{u['id']}={v} outside [0,{u['available_kw']}]")
    for u in p["oil"]:
        v = sp[u["id"]]; total += v; cost += dt * u["cost_per_kwh"] * v
        lo, hi = (u["min_kw"], u["max_kw"]) if u["running"] else (0, 0)
        need(lo - TOL <= v <= hi + TOL, f"{u['id']}={v} outside [{lo},{hi}]")
    for k in p["storage"]:
        v = sp[k["id"]]; total += v
        dis, ch = max(v, 0.0), max(-v, 0.0)
        cost += dt * k["cycle_cost_per_kwh"] * (ch + dis)
        need(ch <= k["max_charge_kw"] + TOL, f"{k['id']} charge {ch}")
        need(dis <= k["max_discharge_kw"] + TOL, f"{k['id']} discharge {dis}")
        need(k["eff_charge"] * ch * dt <= k["soc_max_kwh"] - k["soc_kwh"] + TOL, f"{k['id']} energy room")
        need(dis * dt / k["eff_discharge"] <= k["soc_kwh"] - k["soc_min_kwh"] + TOL, f"{k['id']} energy left")
    shed = s["shed_kw"]; total += shed; cost += dt * p["voll_per_kwh"] * shed
    need(-TOL <= shed <= p["demand_kw"] + TOL, f"shed {shed}")
    need(abs(total - p["demand_kw"]) <= TOL, f"balance off by {total - p['demand_kw']}")
    return err, cost


def check_multi(p, s):
    err, dt, nt = [], p["dt_h"], len(p["periods"])
    w = p.get("smoothing_cost_per_kw2", 0.0)
    rz = p.get("reserve")
    R = lambda u: u.get("ramp_kw_per_s", 0) * 3600 * dt
    def need(cond, msg):
        if not cond:
            err.append(msg)
    cost = 0.0
    soc = {k["id"]: k["soc_kwh"] for k in p["storage"]}
    last = {}
    for t, (per, r) in enumerate(zip(p["periods"], s["periods"])):
        sp, total = r["setpoints_kw"], 0.0
        ren_total, req, head = 0.0, 0.0, 0.0
        if rz:
            req = rz.get("load_frac", 0) * per["demand_kw"]
        for kind in ("pv", "wind"):
            for u in p[kind]:
                v = sp[u["id"]]; total += v; ren_total += v; cost += dt * u["cost_per_kwh"] * v
                need(-TOL <= v <= per["available_kw"][u["id"]] + TOL, f"t{t} {u['id']} bounds")
                if rz:
                    req += rz.get(f"{kind}_frac", 0) * v
                prv = last.get(u["id"], u.get("initial_kw"))
                if R(u) > 0 and prv is not None:
                    need(v - prv <= R(u) + TOL, f"t{t} {u['id']} ramp")
                if w > 0 and prv is not None:
                    cost += w * (v - prv) ** 2
                last[u["id"]] = v
        for u in p["oil"]:
            v = sp[u["id"]]; total += v; cost += dt * u["cost_per_kwh"] * v
            run = running(p, t, u)
            lo, hi = (u["min_kw"], u["max_kw"]) if run else (0, 0)
            need(lo - TOL <= v <= hi + TOL, f"t{t} {u['id']} bounds")
            if run:
                head += u["max_kw"] - v
            prv = last.get(u["id"], u.get("initial_kw"))
            was = running(p, t - 1, u) if t > 0 else ("initial_kw" in u)
            if R(u) > 0 and run and was:
                need(abs(v - prv) <= R(u) + TOL, f"t{t} {u['id']} ramp {v} vs {prv}")
            if w > 0 and prv is not None:
                cost += w * (v - prv) ** 2
            last[u["id"]] = v
        for k in p["storage"]:
            ch, dis = r["charge_kw"][k["id"]], r["discharge_kw"][k["id"]]
            v = sp[k["id"]]; total += v
            need(abs(v - (dis - ch)) <= 1e-9, f"t{t} {k['id']} net")
            need(-TOL <= ch <= k["max_charge_kw"] + TOL, f"t{t} {k['id']} charge")
            need(-TOL <= dis <= k["max_discharge_kw"] + TOL, f"t{t} {k['id']} discharge")
            cost += dt * k["cycle_cost_per_kwh"] * (ch + dis)
            before = soc[k["id"]]
            soc[k["id"]] = before + k["eff_charge"] * dt * ch - dt * dis / k["eff_discharge"]
            need(k["soc_min_kwh"] - TOL <= soc[k["id"]] <= k["soc_max_kwh"] + TOL, f"t{t} {k['id']} soc {soc[k['id']]}")
            need(abs(soc[k["id"]] - r["soc_kwh"][k["id"]]) <= TOL, f"t{t} {k['id']} reported soc")
            if rz:
                head += max(0.0, min(k["max_discharge_kw"] - v,
                                     (before - k["soc_min_kwh"]) * k["eff_discharge"] / dt - v))
            prv = last.get(k["id"], k.get("initial_kw"))
            if R(k) > 0 and prv is not None:
                need(abs(v - prv) <= R(k) + TOL, f"t{t} {k['id']} ramp")
            if w > 0 and prv is not None:
                cost += w * (v - prv) ** 2
            last[k["id"]] = v
        shed = r["shed_kw"]; total += shed; cost += dt * p["voll_per_kwh"] * shed
        need(-TOL <= shed <= per["demand_kw"] + TOL, f"t{t} shed")
        need(abs(total - per["demand_kw"]) <= TOL, f"t{t} balance off by {total - per['demand_kw']}")
        if rz:
            sf = r["reserve_shortfall_kw"]
            need(sf >= -TOL, f"t{t} shortfall < 0")
            need(head + sf >= req - TOL, f"t{t} reserve {head}+{sf} < {req}")
            cost += dt * rz["shortfall_cost_per_kwh"] * sf
        if "max_renewable_share" in p:
            need(ren_total <= p["max_renewable_share"] * per["demand_kw"] + TOL, f"t{t} share")
    for k in p["storage"]:
        cost -= k.get("terminal_value_per_kwh", 0) * soc[k["id"]]
    return err, cost


def check_commit(p, s, hobj):
    """Our commitment answer against HiGHS's MILP optimum: the objective within
    the search's gap (0.1 %, or the gap it reports when unproven), and the
    schedule it chose, fixed, is feasible and costs what it says."""
    import copy
    errs = []
    c = s.get("commitment")
    if not c:
        return ["no commitment in the answer"]
    gap = 1e-3 * max(1.0, abs(hobj)) + 1e-6
    if s["objective"] < hobj - 1e-5 * max(1.0, abs(hobj)):
        errs.append(f"objective {s['objective']!r} below HiGHS's optimum {hobj!r}")
    if c["proven"] and s["objective"] > hobj + gap:
        errs.append(f"proven objective {s['objective']!r} vs HiGHS {hobj!r}")
    if not c["proven"] and s["objective"] > hobj * 1.01 + 1e-6:
        errs.append(f"unproven objective {s['objective']!r} more than 1 % above HiGHS {hobj!r}")
    if c["lower_bound"] > hobj + gap:
        errs.append(f"lower bound {c['lower_bound']!r} above HiGHS's optimum {hobj!r}")
    fixed = copy.deepcopy(p)
    extra = 0.0
    for u in fixed["oil"]:
        sched = c["running"][u["id"]]
        prev = u["running"]
        for t, on in enumerate(sched):
            fixed["periods"][t].setdefault("running", {})[u["id"]] = on
            extra += p["dt_h"] * u["no_load_cost_per_h"] * on + u["start_cost"] * (on and not prev)
            prev = on
        u.pop("initial_kw", None)
    e, recomputed = check_multi(fixed, s)
    errs += e
    if not rel_ok(recomputed + extra, s["objective"]):
        errs.append(f"objective {s['objective']!r} but setpoints and schedule cost {recomputed + extra!r}")
    return errs


# ------------------------------------------------------------------- main


def pct(xs, q):
    return float(np.percentile(xs, q)) if xs else float("nan")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("bin", nargs="?", default=os.environ.get("GRIDSCADA_BIN"))
    ap.add_argument("--single", type=int, default=200)
    ap.add_argument("--multi", type=int, default=50)
    ap.add_argument("--commit", type=int, default=40)
    ap.add_argument("--seed", type=int, default=20240601)
    a = ap.parse_args()
    if not a.bin:
        sys.exit("give the gridscada binary as an argument or in GRIDSCADA_BIN")
    rng = random.Random(a.seed)
    singles = [gen_single(rng, i) for i in range(a.single)]
    multis = [gen_multi(rng, i) for i in range(a.multi)]
    commits = [gen_commit(rng, i) for i in range(a.commit)]
    problems = singles + multis + commits

    t0 = time.perf_counter()
    proc = subprocess.run([a.bin, "dispatch", "solve", "-"], input=json.dumps(problems),
                          capture_output=True, text=True)
    wall = time.perf_counter() - t0
    if proc.returncode == 1 or not proc.stdout.strip():
        sys.exit(f"binary failed (exit {proc.returncode}): {proc.stderr[:2000]}")
    answers = json.loads(proc.stdout)
    assert len(answers) == len(problems)

    passed, failed = 0, 0
    ours_ms = {"single": [], "multi": [], "commit": []}
    highs_ms = {"single": [], "multi": [], "commit": []}
    for i, (p, s) in enumerate(zip(problems, answers)):
        if "periods" not in p:
            kind = "single"
        elif any(u.get("optimize_commitment") for u in p["oil"]):
            kind = "commit"
        else:
            kind = "multi"
        solver = {"single": highs_single, "multi": highs_multi, "commit": highs_commit}[kind]
        hs, hobj, hms = solver(p)
        highs_ms[kind].append(hms)
        problems_found = []
        if s["status"] == "optimal":
            ours_ms[kind].append(s["solve_ms"])
        if s["status"] != hs:
            problems_found.append(f"status {s['status']} vs HiGHS {hs} ({s.get('reason', '')})")
        elif hs == "optimal" and kind == "commit":
            problems_found += check_commit(p, s, hobj)
        elif hs == "optimal":
            if not rel_ok(s["objective"], hobj):
                problems_found.append(f"objective {s['objective']!r} vs HiGHS {hobj!r}")
            errs, recomputed = (check_multi if kind == "multi" else check_single)(p, s)
            problems_found += errs
            if not rel_ok(recomputed, s["objective"]):
                problems_found.append(f"objective {s['objective']!r} but setpoints cost {recomputed!r}")
        if problems_found:
            failed += 1
            print(f"instance {i} ({kind}): " + "; ".join(problems_found[:5]))
        else:
            passed += 1

    for kind in ("single", "multi", "commit"):
        print(f"{kind}: gridscada solve_ms p50 {pct(ours_ms[kind], 50):.3f} p99 {pct(ours_ms[kind], 99):.3f}; "
              f"HiGHS p50 {pct(highs_ms[kind], 50):.3f} p99 {pct(highs_ms[kind], 99):.3f}")
    print(f"batch wall time {wall:.2f} s for {len(problems)} problems")
    infeasible = sum(1 for s in answers if s["status"] == "infeasible")
    print(f"({infeasible} instances infeasible in both)" if infeasible else "")
    print(f"{passed} passed, {failed} failed")
    sys.exit(1 if failed else 0)


if __name__ == "__main__":
    main()
