//! Tests of the outer loop: one period at a time against a tag database and
//! a fake writer, and the task publishing its status and notices.

use std::sync::Arc;
use std::time::Duration;

use tokio::sync::{mpsc, watch};

use super::*;
use gridscada_tagdb::{Clock, Quality, Sample, TagMeta, ValueKind, WriteError, WriteFuture};
use std::sync::Mutex;

const CFG: &str = r#"
dispatch_period_s = 5.0
voll_per_kwh = 5.0
demand_tag = "MG.Load.P_kW"
stale_after_s = 15.0

[commitment]
start_soc_frac = 0.25
stop_soc_frac = 0.6
min_run_s = 900.0
min_stop_s = 300.0

[[unit]]
id = "pv1"
kind = "pv"
name = "PV array"
prefix = "MG.PV1"
rated_kw = 100.0

[[unit]]
id = "bess1"
kind = "storage"
name = "Battery"
prefix = "MG.BESS1"
capacity_kwh = 200.0
soc_min_kwh = 20.0
soc_max_kwh = 190.0
max_charge_kw = 50.0
max_discharge_kw = 60.0
cycle_cost_per_kwh = 0.02

[[unit]]
id = "dg1"
kind = "diesel"
name = "Diesel"
prefix = "MG.DG1"
min_kw = 30.0
max_kw = 150.0
cost_per_kwh = 0.35
"#;

fn config() -> MicrogridConfig {
    toml::from_str(CFG).unwrap()
}

fn db(cfg: &MicrogridConfig) -> Arc<TagDb> {
    let mut metas = vec![TagMeta::new(
        cfg.demand_tag.get_ref().as_str(),
        ValueKind::Float,
    )];
    for u in &cfg.units {
        for t in u.required_tags() {
            let kind = if t.ends_with("Running") || t.ends_with("RunCmd") {
                ValueKind::Bool
            } else {
                ValueKind::Float
            };
            metas.push(TagMeta::new(t.as_str(), kind).writable(true));
        }
    }
    Arc::new(TagDb::new(metas).unwrap())
}

/// Confirms writes by storing them in the tag database; can fail one tag.
struct FakeWriter {
    db: Arc<TagDb>,
    now: Mutex<Timestamp>,
    fail: Mutex<Option<String>>,
    log: Mutex<Vec<(String, Value)>>,
}

impl TagWriter for FakeWriter {
    fn write<'a>(&'a self, name: &'a str, value: Value) -> WriteFuture<'a> {
        Box::pin(async move {
            if self.fail.lock().unwrap().as_deref() == Some(name) {
                return Err(WriteError::Timeout(name.to_string()));
            }
            let id = self
                .db
                .id(name)
                .ok_or_else(|| WriteError::UnknownTag(name.into()))?;
            let s = Sample {
                value: value.clone(),
                quality: Quality::GOOD,
                timestamp: *self.now.lock().unwrap(),
            };
            self.db.apply([(id, s.clone())]);
            self.log.lock().unwrap().push((name.to_string(), value));
            Ok(s)
        })
    }
}

fn set(db: &TagDb, name: &str, v: impl Into<Value>, at: Timestamp) {
    db.set(db.id(name).unwrap(), v, Quality::GOOD, at);
}

fn plant(db: &TagDb, at: Timestamp, demand: f64, pv: f64, soc: f64, running: bool) {
    set(db, "MG.Load.P_kW", demand, at);
    set(db, "MG.PV1.Available_kW", pv, at);
    set(db, "MG.BESS1.SoC_kWh", soc, at);
    set(db, "MG.DG1.Running", running, at);
}

fn written(w: &FakeWriter, tag: &str) -> Option<Value> {
    w.log
        .lock()
        .unwrap()
        .iter()
        .rev()
        .find(|(n, _)| n == tag)
        .map(|(_, v)| v.clone())
}

fn fake_writer(db: &Arc<TagDb>, now: Timestamp) -> FakeWriter {
    FakeWriter {
        db: db.clone(),
        now: Mutex::new(now),
        fail: Mutex::new(None),
        log: Mutex::new(Vec::new()),
    }
}

fn fixture() -> (MicrogridConfig, Arc<TagDb>, FakeWriter) {
    let cfg = config();
    let db = db(&cfg);
    let w = fake_writer(&db, Timestamp::from_millis(0));
    (cfg, db, w)
}

#[tokio::test]
async fn optimal_period_writes_balanced_setpoints() {
    let (cfg, db, w) = fixture();
    let now = Timestamp::from_millis(1_000_000);
    plant(&db, now, 150.0, 60.0, 100.0, true);
    let mut d = Dispatcher::new(cfg, now);
    let (st, notices) = d.step(&db, &w, now).await;
    assert_eq!(st.mode, DispatchMode::Optimal, "{:?}", st.reason);
    assert_eq!(st.status, "optimal");
    // PV 60, battery 60, diesel 30.
    assert_eq!(
        written(&w, "MG.PV1.Setpoint_kW")
            .and_then(|v| v.as_f64())
            .map(|v| v.round()),
        Some(60.0)
    );
    assert_eq!(
        written(&w, "MG.BESS1.Setpoint_kW")
            .and_then(|v| v.as_f64())
            .map(|v| v.round()),
        Some(60.0)
    );
    assert_eq!(
        written(&w, "MG.DG1.Setpoint_kW")
            .and_then(|v| v.as_f64())
            .map(|v| v.round()),
        Some(30.0)
    );
    assert_eq!(written(&w, "MG.DG1.RunCmd"), Some(Value::Bool(true)));
    let total: f64 = st.setpoints_kw.0.iter().map(|(_, v)| v).sum::<f64>() + st.shed_kw;
    assert!((total - 150.0).abs() < 1e-6);
    assert!(notices
        .iter()
        .all(|n| !matches!(n, DispatchNotice::Alarm { .. })));
    serde_json::to_string(&st).unwrap();
}

#[tokio::test]
async fn stale_or_bad_measurements_fall_back_and_raise_then_clear_the_alarm() {
    let (cfg, db, w) = fixture();
    let t0 = Timestamp::from_millis(1_000_000);
    plant(&db, t0, 150.0, 60.0, 100.0, true);
    let mut d = Dispatcher::new(cfg, t0);
    d.step(&db, &w, t0).await;
    // 20 s later nothing was refreshed: stale.
    let t1 = t0.add(Duration::from_secs(20));
    let (st, notices) = d.step(&db, &w, t1).await;
    assert_eq!(st.mode, DispatchMode::Fallback);
    assert!(
        st.reason.as_deref().unwrap().contains("stale"),
        "{:?}",
        st.reason
    );
    assert!(notices.iter().any(
        |n| matches!(n, DispatchNotice::Alarm { active: true, name, .. } if name == FALLBACK_ALARM)
    ));
    // Fallback still writes sane, balanced setpoints from the held values.
    let total: f64 = st.setpoints_kw.0.iter().map(|(_, v)| v).sum::<f64>() + st.shed_kw;
    assert!((total - 150.0).abs() < 1e-6);
    // A Bad quality demand also falls back (alarm already active: no new raise).
    plant(&db, t1, 150.0, 60.0, 100.0, true);
    db.set(
        db.id("MG.Load.P_kW").unwrap(),
        150.0,
        Quality::bad("comm failure"),
        t1,
    );
    let (st, notices) = d.step(&db, &w, t1).await;
    assert_eq!(st.mode, DispatchMode::Fallback);
    assert!(st.reason.as_deref().unwrap().contains("Bad"));
    assert!(notices.is_empty());
    // Fresh and good again: optimal, alarm cleared.
    plant(&db, t1, 150.0, 60.0, 100.0, true);
    let (st, notices) = d.step(&db, &w, t1).await;
    assert_eq!(st.mode, DispatchMode::Optimal);
    assert!(notices
        .iter()
        .any(|n| matches!(n, DispatchNotice::Alarm { active: false, .. })));
}

/// The fixture's plant with a look-ahead whose demand curve is `demand`.
fn with_horizon(demand: &str) -> MicrogridConfig {
    toml::from_str(&format!(
        "{CFG}\n[horizon]\nperiods = 16\nperiod_s = 900.0\nresolve_s = 60.0\n\
         blend_h = 2.0\ndemand_forecast_kw = {demand}\n"
    ))
    .unwrap()
}

const FIVE_PM: i64 = 17 * 3_600_000;

#[tokio::test]
async fn look_ahead_charges_from_the_running_diesel_before_an_evening_peak() {
    // 17:00, diesel running, 60 kW demand, no sun, battery at 40 kWh.
    // The forecast peak of 200 kW at 19:00-20:00 exceeds the diesel's
    // 150 kW plus what 40 kWh can give: energy stored now averts shedding.
    let peak = "[[0, 60], [17, 60], [18.5, 200], [20.5, 200], [21, 60]]";
    let now = Timestamp::from_millis(FIVE_PM);
    let run = |cfg: MicrogridConfig| async move {
        let db = db(&cfg);
        let w = fake_writer(&db, now);
        plant(&db, now, 60.0, 0.0, 40.0, true);
        let mut d = Dispatcher::new(cfg, now);
        d.step(&db, &w, now).await
    };
    let (ahead, notices) = run(with_horizon(peak)).await;
    assert_eq!(ahead.mode, DispatchMode::Optimal, "{:?}", ahead.reason);
    let plan = ahead.horizon.as_ref().expect("a plan");
    assert_eq!(plan.status, "optimal", "{:?}", plan.reason);
    assert_eq!(plan.periods, 16);
    assert_eq!(plan.demand_kw[0], 60.0);
    assert!(
        plan.demand_kw.iter().any(|d| *d > 190.0),
        "{:?}",
        plan.demand_kw
    );
    let value = plan.stored_energy_value_per_kwh.get("bess1").unwrap();
    assert!(value > 1.0, "stored energy averts shedding: {value}");
    // The dispatch priced stored energy at the plan's value (capped) and
    // charges the battery from the diesel at full rate.
    let priced = ahead.inputs.as_ref().unwrap().storage[0].stored_value_per_kwh;
    assert!((priced - value.min(0.9 * 5.0 * 0.95)).abs() < 1e-9);
    let bess = ahead.setpoints_kw.get("bess1").unwrap();
    let dg = ahead.setpoints_kw.get("dg1").unwrap();
    assert!(
        (bess + 50.0).abs() < 1e-3,
        "battery charges at 50 kW: {bess}"
    );
    assert!((dg - 110.0).abs() < 1e-3, "diesel 60 + 50 kW: {dg}");
    assert!(notices
        .iter()
        .all(|n| !matches!(n, DispatchNotice::Alarm { .. })));
    // Without the look-ahead the same moment discharges the battery to
    // the diesel's minimum load instead.
    let (alone, _) = run(config()).await;
    assert!(alone.horizon.is_none());
    assert!(alone.setpoints_kw.get("bess1").unwrap() > 0.0, "{alone:?}");
}

#[tokio::test]
async fn the_plan_is_renewed_every_resolve_interval_and_a_failed_one_is_reported() {
    // The diesel just restarted (held on by its minimum run time) meets
    // 10 kW of demand, and the battery is all but full. This 5 s period
    // can store the excess; a 15-minute look-ahead period cannot, so no
    // plan exists.
    let cfg = with_horizon("[[0, 60]]");
    let db = db(&cfg);
    let t0 = Timestamp::from_millis(FIVE_PM);
    let w = fake_writer(&db, t0);
    plant(&db, t0, 10.0, 0.0, 189.9, true);
    let mut d = Dispatcher::new(cfg, t0);
    let (st, notices) = d.step(&db, &w, t0).await;
    let plan = st.horizon.as_ref().unwrap();
    assert_eq!(plan.status, "infeasible", "{plan:?}");
    assert!(notices.iter().any(|n| matches!(n,
        DispatchNotice::Event { message, .. } if message.contains("look-ahead failed"))));
    // The dispatch itself goes on, optimal, with the fixed estimate.
    assert_eq!(st.mode, DispatchMode::Optimal, "{:?}", st.reason);
    let fixed = stored_energy_value(&d.cfg, &d.cfg.units[1]);
    assert_eq!(
        st.inputs.as_ref().unwrap().storage[0].stored_value_per_kwh,
        fixed
    );
    // 5 s later: no new plan yet, no repeated event.
    let t1 = t0.add(Duration::from_secs(5));
    plant(&db, t1, 10.0, 0.0, 189.9, true);
    let (st, notices) = d.step(&db, &w, t1).await;
    assert_eq!(st.horizon.as_ref().unwrap().at, t0);
    assert!(notices.is_empty(), "{notices:?}");
    // A minute on, demand is back: planned again, and said so.
    let t2 = t0.add(Duration::from_secs(60));
    plant(&db, t2, 60.0, 0.0, 20.0, true);
    let (st, notices) = d.step(&db, &w, t2).await;
    let plan = st.horizon.as_ref().unwrap();
    assert_eq!((plan.at, plan.status.as_str()), (t2, "optimal"), "{plan:?}");
    assert!(notices.iter().any(|n| matches!(n,
        DispatchNotice::Event { message, .. } if message.contains("planning again"))));
}

#[tokio::test]
async fn a_plan_is_used_adopt_after_s_after_its_measurements() {
    // As above, with adopt_after_s = 30: the failed first plan (the first
    // plan is adopted at once) stands until the next one's time.
    let cfg: MicrogridConfig = toml::from_str(&format!(
        "{CFG}\n[horizon]\nperiods = 16\nperiod_s = 900.0\nresolve_s = 60.0\n\
         adopt_after_s = 30\nblend_h = 2.0\ndemand_forecast_kw = [[0, 60]]\n"
    ))
    .unwrap();
    let db = db(&cfg);
    let t0 = Timestamp::from_millis(FIVE_PM);
    let w = fake_writer(&db, t0);
    plant(&db, t0, 10.0, 0.0, 189.9, true);
    let mut d = Dispatcher::new(cfg, t0);
    let (st, _) = d.step(&db, &w, t0).await;
    assert_eq!(st.horizon.as_ref().unwrap().status, "infeasible");
    // A minute on, demand is back: a plan is made from what is measured
    // now, and used 30 s later however soon its solve ends.
    let t2 = t0.add(Duration::from_secs(60));
    plant(&db, t2, 60.0, 0.0, 20.0, true);
    let (st, notices) = d.step(&db, &w, t2).await;
    assert_eq!(st.horizon.as_ref().unwrap().at, t0);
    assert!(notices.is_empty(), "{notices:?}");
    std::thread::sleep(Duration::from_millis(300));
    let t3 = t2.add(Duration::from_secs(25));
    plant(&db, t3, 60.0, 0.0, 20.0, true);
    let (st, _) = d.step(&db, &w, t3).await;
    assert_eq!(st.horizon.as_ref().unwrap().at, t0, "not before its time");
    // Adopted at its time even though the measurements then are unusable:
    // it was made from usable ones.
    let t4 = t2.add(Duration::from_secs(30));
    plant(&db, t4, 60.0, 0.0, 20.0, true);
    db.set(
        db.id("MG.Load.P_kW").unwrap(),
        60.0,
        Quality::bad("comm failure"),
        t4,
    );
    let (st, notices) = d.step(&db, &w, t4).await;
    let plan = st.horizon.as_ref().unwrap();
    assert_eq!((plan.at, plan.status.as_str()), (t2, "optimal"), "{plan:?}");
    assert_eq!(plan.demand_kw[0], 60.0, "the plan saw the demand at t2");
    assert!(notices.iter().any(|n| matches!(n,
        DispatchNotice::Event { message, .. } if message.contains("planning again"))));
}

#[tokio::test]
async fn by_default_a_plan_is_used_in_the_period_it_is_made() {
    let cfg = with_horizon("[[0, 60]]");
    assert_eq!(cfg.horizon.as_ref().unwrap().adopt_after_s(), 0.0);
    let db = db(&cfg);
    let t0 = Timestamp::from_millis(FIVE_PM);
    let w = fake_writer(&db, t0);
    let mut d = Dispatcher::new(cfg, t0);
    for (i, demand) in [60.0, 70.0, 80.0].into_iter().enumerate() {
        let t = t0.add(Duration::from_secs(60 * i as u64));
        plant(&db, t, demand, 0.0, 100.0, true);
        let (st, _) = d.step(&db, &w, t).await;
        let plan = st.horizon.as_ref().unwrap();
        assert_eq!((plan.at, plan.demand_kw[0]), (t, demand), "{plan:?}");
    }
}

#[tokio::test]
async fn failed_write_switches_to_the_rule() {
    let (cfg, db, w) = fixture();
    let now = Timestamp::from_millis(1_000_000);
    plant(&db, now, 150.0, 60.0, 100.0, true);
    *w.fail.lock().unwrap() = Some("MG.BESS1.Setpoint_kW".into());
    let mut d = Dispatcher::new(cfg, now);
    let (st, notices) = d.step(&db, &w, now).await;
    assert_eq!(st.mode, DispatchMode::Fallback);
    assert!(st
        .reason
        .as_deref()
        .unwrap()
        .contains("MG.BESS1.Setpoint_kW"));
    assert!(!st.write_failures.is_empty());
    assert!(notices
        .iter()
        .any(|n| matches!(n, DispatchNotice::Alarm { active: true, .. })));
    // The other units still got setpoints.
    assert!(written(&w, "MG.PV1.Setpoint_kW").is_some());
    assert!(written(&w, "MG.DG1.Setpoint_kW").is_some());
}

#[tokio::test]
async fn diesel_is_started_by_the_rule_and_only_loaded_once_running() {
    let (cfg, db, w) = fixture();
    let now = Timestamp::from_millis(1_000_000);
    // Net load 200 - 20 = 180 kW, far beyond the battery: start dg1.
    plant(&db, now, 200.0, 20.0, 100.0, false);
    let mut d = Dispatcher::new(cfg, now);
    let (st, notices) = d.step(&db, &w, now).await;
    assert_eq!(written(&w, "MG.DG1.RunCmd"), Some(Value::Bool(true)));
    assert!(notices.iter().any(
        |n| matches!(n, DispatchNotice::Event { message, .. } if message.contains("dg1 start"))
    ));
    // Not yet running: zero setpoint and the deficit is shed.
    assert_eq!(st.setpoints_kw.get("dg1"), Some(0.0));
    assert!(st.shed_kw > 100.0);
    // Next period it reports running: loaded.
    let t1 = now.add(Duration::from_secs(5));
    plant(&db, t1, 200.0, 20.0, 100.0, true);
    let (st, _) = d.step(&db, &w, t1).await;
    assert!(st.setpoints_kw.get("dg1").unwrap() > 100.0);
    assert!(st.shed_kw < 1e-6);
}

#[tokio::test]
async fn rule_policy_never_solves_and_raises_no_alarm() {
    let (cfg, db, w) = fixture();
    let now = Timestamp::from_millis(1_000_000);
    plant(&db, now, 150.0, 60.0, 100.0, true);
    let mut d = Dispatcher::new(cfg, now).with_policy(DispatchPolicy::Rule);
    let (st, notices) = d.step(&db, &w, now).await;
    assert_eq!(st.status, "rule");
    assert_eq!(st.mode, DispatchMode::Fallback);
    assert!(st.objective.is_none());
    assert!(st.reason.is_none(), "{:?}", st.reason);
    assert!(notices
        .iter()
        .all(|n| !matches!(n, DispatchNotice::Alarm { .. })));
    let total: f64 = st.setpoints_kw.0.iter().map(|(_, v)| v).sum::<f64>() + st.shed_kw;
    assert!((total - 150.0).abs() < 1e-6);
}

/// A plant clock for the loop: sleeping advances plant time at once.
struct StepClock(Mutex<Timestamp>);
impl Clock for StepClock {
    fn now(&self) -> Timestamp {
        *self.0.lock().unwrap()
    }
    fn sleep(
        &self,
        d: Duration,
    ) -> std::pin::Pin<Box<dyn std::future::Future<Output = ()> + Send>> {
        let mut t = self.0.lock().unwrap();
        *t = t.add(d);
        Box::pin(tokio::task::yield_now())
    }
}

#[tokio::test]
async fn run_dispatch_publishes_status_and_notices() {
    let (cfg, db, w) = fixture();
    // Stale measurements at start: a fallback alarm must arrive.
    plant(&db, Timestamp::from_millis(0), 150.0, 60.0, 100.0, true);
    let clock = Arc::new(StepClock(Mutex::new(Timestamp::from_millis(1_000_000))));
    let (stx, mut srx) = watch::channel(DispatchStatus::default());
    let (ntx, mut nrx) = mpsc::channel(16);
    let task = tokio::spawn(run_dispatch(cfg, db.clone(), Arc::new(w), clock, stx, ntx));
    loop {
        let n = nrx.recv().await.unwrap();
        if let DispatchNotice::Alarm {
            active,
            name,
            reason,
            ..
        } = n
        {
            assert!(
                active && name == FALLBACK_ALARM && reason.contains("stale"),
                "{reason}"
            );
            break;
        }
    }
    srx.changed().await.unwrap();
    assert_eq!(srx.borrow().mode, DispatchMode::Fallback);
    task.abort();
}

/// A slow look-ahead must not hold up the server's other tasks: the pair's
/// lease renewal shares the runtime, and a plan that took seconds in a
/// debug build once let the lease run out and the pair flap.
#[tokio::test(flavor = "multi_thread", worker_threads = 1)]
async fn waiting_for_a_slow_plan_leaves_the_runtime_to_other_tasks() {
    let now = Timestamp::from_millis(1_000);
    let slow = PlanSolve {
        thread: Some(std::thread::spawn(move || {
            std::thread::sleep(Duration::from_millis(600));
            HorizonPlan::failed(now, "slow on purpose".into())
        })),
        now,
    };
    let ticks = Arc::new(std::sync::atomic::AtomicU32::new(0));
    let counter = ticks.clone();
    let ticker = tokio::spawn(async move {
        loop {
            tokio::time::sleep(Duration::from_millis(20)).await;
            counter.fetch_add(1, std::sync::atomic::Ordering::SeqCst);
        }
    });
    // Let the ticker start on the only worker, then wait there.
    tokio::time::sleep(Duration::from_millis(30)).await;
    let before = ticks.load(std::sync::atomic::Ordering::SeqCst);
    let plan = tokio::spawn(async move { slow.finish() }).await.unwrap();
    let during = ticks.load(std::sync::atomic::Ordering::SeqCst) - before;
    ticker.abort();
    assert_eq!(plan.reason.as_deref(), Some("slow on purpose"));
    assert!(
        during >= 10,
        "the other task ran {during} times in the 600 ms wait"
    );
}
