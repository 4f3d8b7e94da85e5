"""Checks a daily report made from scenarios/report-known-day.toml against
the totals worked out by hand in the scenario's header, and its PDF (printed
by Chromium) for the title text and a page that is not blank.

    reports_check.py REPORT.json [REPORT.pdf PAGE1.png PDF.txt]
"""
import json
import sys


def close(name, got, want, rel=None, abs_=None):
    tol = abs_ if abs_ is not None else abs(want) * rel
    ok = got is not None and abs(got - want) <= tol
    print(f"  {'pass' if ok else 'FAIL'} {name}: {got} (want {want} ± {tol:g})")
    return ok


def main():
    r = json.load(open(sys.argv[1]))
    ok = True
    panels = {p["id"]: p for p in r["energy"]["panels"]}
    # The run covers 00:00-02:00 (recording stops with the replay).
    ok &= close("SS1 kWh (14 kW × 2 h − 4 kWh not supplied)", panels["ss1"]["kwh"], 24.0, rel=0.01)
    ok &= close("CSS1 kWh (10 kW × 2 h)", panels["css1"]["kwh"], 20.0, rel=0.01)
    ok &= close("data coverage of the day (2 h of 24)", panels["ss1"]["coverage"] * 24, 2.0, abs_=0.05)

    ints = r["outages"]["interruptions"]
    z2 = [i for i in ints if i["panel"] == "ss1" and i["zone"] == 2 and i["sustained"]]
    print(f"  {'pass' if len(z2) == 1 else 'FAIL'} one sustained interruption of SS1 zone 2: {len(z2)}")
    ok &= len(z2) == 1
    if z2:
        ok &= close("its duration, s (00:30 to the Reset at 01:30)", z2[0]["duration_s"], 3600.0, abs_=15.0)
        ok &= close("its energy not supplied, kWh (4 kW × 1 h)", z2[0]["ens_kwh"], 4.0, rel=0.02)
    others = [i for i in ints if i["sustained"] and not (i["panel"] == "ss1" and i["zone"] == 2)]
    print(f"  {'pass' if not others else 'FAIL'} no other sustained interruption: {others}")
    ok &= not others
    css1_ints = [i for i in ints if i["panel"] == "css1"]
    print(f"  {'pass' if not css1_ints else 'FAIL'} no interruption on CSS1: {len(css1_ints)}")
    ok &= not css1_ints
    rel = {p["id"]: p for p in r["outages"]["panels"]}
    ok &= close("SS1 SAIFI (1 sustained / 4 zones)", rel["ss1"]["saifi"], 0.25, abs_=1e-9)
    ok &= close("SS1 SAIDI, min (60 min / 4 zones)", rel["ss1"]["saidi_min"], 15.0, abs_=0.25)
    # Every SS1 zone was out while the ELCB was open during the sequence.
    moment = rel["ss1"]["momentary"]
    print(f"  {'pass' if moment >= 3 else 'FAIL'} momentary interruptions on SS1 (trips during the sequence): {moment}")
    ok &= moment >= 3
    ok &= close("SS1 energy not supplied, kWh", rel["ss1"]["ens_kwh"], 4.0, rel=0.03)

    e = r["energy"]
    units = {u["id"]: u for u in e["units"]}
    charged = sum(u["charged_kwh"] for u in e["units"])
    ok &= close("microgrid demand, kWh (40 kW × 2 h)", e["demand_kwh"], 80.0, rel=0.01)
    ok &= close("production − charging = demand, kWh", e["produced_kwh"] - charged, e["demand_kwh"], rel=0.02)
    ok &= close("no sun: PV kWh", units["pv1"]["kwh"], 0.0, abs_=0.01)
    share = e["renewable_share"]
    ok &= close("PV/wind share = wind / production", share, units["wt1"]["kwh"] / e["produced_kwh"], abs_=1e-9)
    a = r["alarms"]
    keys = {t["alarm_key"]: t["count"] for t in a["top"]}
    want = ["SS1.ELCB.Closed:discrete", "ss1:zone2.isolated"]
    has = all(keys.get(k, 0) >= 1 for k in want)
    print(f"  {'pass' if has else 'FAIL'} the fault's alarms among the top alarms: {keys}")
    ok &= has
    # Each top alarm says where it is, by the configured name: the
    # sequence's alarm (no tag) its panel's.
    names = {p["id"]: p["name"] for p in r["energy"]["panels"]}
    places = {t["alarm_key"]: t["place"] for t in a["top"]}
    placed = all(places.values()) and places.get("ss1:zone2.isolated") == names["ss1"]
    print(f"  {'pass' if placed else 'FAIL'} every top alarm placed, the sequence's on its panel: {places}")
    ok &= placed
    currency = r.get("currency")
    print(f"  {'pass' if currency == 'EUR' else 'FAIL'} costs in the demo's [reports] currency: {currency}")
    ok &= currency == "EUR"
    # The operator acknowledges everything at 01:25 (5100 s into the day).
    every = a["activations"] >= 2 and a["acknowledged"] == a["activations"]
    print(f"  {'pass' if every else 'FAIL'} every activation acknowledged: {a['acknowledged']} of {a['activations']}")
    ok &= every
    ok &= close("time to acknowledge the ELCB trip at 00:30, s (the median)", a["ack_median_s"], 3300.0, abs_=1800.0)
    in_range = a["ack_max_s"] is not None and a["ack_max_s"] <= 5100.0 + 5
    print(f"  {'pass' if in_range else 'FAIL'} no time to acknowledge beyond 01:25: {a['ack_max_s']}")
    ok &= in_range

    if len(sys.argv) > 2:
        pdf, png, txt = sys.argv[2:5]
        text = open(txt, encoding="utf-8", errors="replace").read()
        title = f"Daily report {r['id']}"
        found = title in text
        print(f"  {'pass' if found else 'FAIL'} the PDF has the title {title!r}")
        ok &= found
        flat = " ".join(text.split())
        for words in ["Definitions", "Battery discharge is in the denominator", f"{names['ss1']} · ss1:zone2.isolated", " EUR"]:
            found = words in flat
            print(f"  {'pass' if found else 'FAIL'} the PDF has {words!r}")
            ok &= found
        from PIL import Image, ImageStat

        img = Image.open(png).convert("L")
        stat = ImageStat.Stat(img)
        dark = img.histogram()[:128]
        dark = sum(dark) / (img.width * img.height)
        # A printed table page: mostly white, with a few percent of ink.
        inked = stat.stddev[0] > 10 and 0.005 < dark < 0.5
        print(f"  {'pass' if inked else 'FAIL'} page 1 is not blank: {img.width}×{img.height}, "
              f"mean {stat.mean[0]:.1f}, stddev {stat.stddev[0]:.1f}, {dark * 100:.1f} % dark")
        ok &= inked
    print("report figures: all pass" if ok else "report figures: FAILED")
    sys.exit(0 if ok else 1)


if __name__ == "__main__":
    main()
