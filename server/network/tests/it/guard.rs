//! The switching guard with a stand-in field writer: other tags pass
//! untouched; a safety tag refuses what it blocks and nothing else; nothing
//! switches before the tags are loaded; operations in flight count, so two
//! closes that are each allowed cannot together parallel the grid and the
//! microgrid; a device another operator has selected is refused from every
//! door until the selection ends; a precheck decides as the write would,
//! without writing.

use std::sync::{Arc, Mutex};
use std::time::Duration;

use gridscada_config::{CommandBinding, StatusBinding};
use gridscada_network::*;
use gridscada_tagdb::{Quality, Sample, TagWriter, Timestamp, Value, WriteError, WriteFuture};
use tokio::sync::{watch, Semaphore};

use crate::cases::{ring, Net};

/// Takes every write, holding each until the test lets it through.
struct Field {
    written: Mutex<Vec<(String, Value)>>,
    gate: Semaphore,
}

impl TagWriter for Field {
    fn write<'a>(&'a self, name: &'a str, value: Value) -> WriteFuture<'a> {
        Box::pin(async move {
            self.written
                .lock()
                .unwrap()
                .push((name.to_string(), value.clone()));
            self.gate.acquire().await.unwrap().forget();
            Ok(Sample {
                value,
                quality: Quality::GOOD,
                timestamp: Timestamp::from_millis(0),
            })
        })
    }
}

struct Rig {
    guard: Arc<SwitchingGuard>,
    field: Arc<Field>,
    tags: SafetyTags,
    selections: Selections,
    _live: watch::Sender<Arc<Live>>,
}

fn rig(open: &[&str]) -> Rig {
    rig_of(ring(), open)
}

fn rig_of(model: Model, open: &[&str]) -> Rig {
    let mut inputs = Inputs::normal(&model);
    for id in open {
        inputs = inputs.with(model.switch(id).unwrap(), Pos::Open);
    }
    let net = Network {
        status: model
            .switches
            .iter()
            .map(|s| Some(StatusBinding::Tag(format!("{}.Closed", s.id))))
            .collect(),
        command: model
            .switches
            .iter()
            .map(|s| Some(CommandBinding::Tag(format!("{}.Cmd", s.id))))
            .collect(),
        in_service: vec![None; model.sources.len()],
        energised: vec![None; model.loads.len()],
        prefix: "NET".into(),
        select_timeout: Duration::from_secs(30),
        model,
    };
    let topology = Arc::new(compute(&net.model, &inputs));
    let (tx, rx) = watch::channel(Arc::new(Live {
        version: 1,
        inputs,
        topology,
    }));
    let field = Arc::new(Field {
        written: Mutex::default(),
        gate: Semaphore::new(0),
    });
    let tags = SafetyTags::default();
    let selections = Selections::new(Duration::from_secs(30));
    let guard = Arc::new(SwitchingGuard::new(
        Arc::new(net),
        field.clone(),
        tags.clone(),
        selections.clone(),
        rx,
        Arc::new(gridscada_tagdb::SystemClock),
    ));
    Rig {
        guard,
        field,
        tags,
        selections,
        _live: tx,
    }
}

fn tag(id: i64, device: &str, kind: TagKind) -> SafetyTag {
    SafetyTag {
        id,
        device: device.into(),
        kind,
        reason: "cable C2 out for jointing".into(),
        work_ref: "WO-1234".into(),
        placed_by: "alice".into(),
        placed_at: Timestamp::from_millis(0),
    }
}

fn blocked(r: Result<Sample, WriteError>) -> gridscada_tagdb::Blocked {
    match r {
        Err(WriteError::Blocked(b)) => b,
        other => panic!("expected a refusal, got {other:?}"),
    }
}

#[tokio::test]
async fn nothing_switches_before_the_tags_are_loaded_and_other_tags_pass() {
    let r = rig(&[]);
    r.field.gate.add_permits(10);
    let b = blocked(r.guard.write("rmu1_s2.Cmd", Value::Bool(false)).await);
    assert!(b.reason.contains("not loaded"), "{b}");
    // A tag that commands no switching device is not the guard's business.
    r.guard
        .write("MG.BESS1.Setpoint_kW", Value::Float(10.0))
        .await
        .unwrap();
    assert_eq!(r.field.written.lock().unwrap().len(), 1);
}

#[tokio::test]
async fn a_do_not_close_tag_refuses_the_close_and_lets_the_open_through() {
    let r = rig(&[]);
    r.field.gate.add_permits(10);
    r.tags.replace(vec![tag(7, "rmu1_s2", TagKind::DoNotClose)]);
    // Open first (allowed), then close (refused, with who, why and the work).
    r.guard
        .write("rmu1_s2.Cmd", Value::Bool(false))
        .await
        .unwrap();
    let b = blocked(
        r.guard
            .precheck("rmu1_s2.Cmd", &Value::Bool(true))
            .map(|_| unreachable!()),
    );
    assert_eq!(b.rule, "safety_tag");
    // The live topology still shows it closed: closing is "already there"
    // only once the position is read back, so test from an open device.
    let r = rig(&["rmu1_s2"]);
    r.field.gate.add_permits(10);
    r.tags.replace(vec![tag(7, "rmu1_s2", TagKind::DoNotClose)]);
    let b = blocked(r.guard.write("rmu1_s2.Cmd", Value::Bool(true)).await);
    assert_eq!(b.rule, "safety_tag");
    assert!(
        b.to_string().contains("DO NOT CLOSE placed by alice") && b.reason.contains("WO-1234"),
        "{b}"
    );
    assert!(
        r.field.written.lock().unwrap().is_empty(),
        "nothing reached the field"
    );
    // Removed: the close goes out.
    r.tags.remove(7);
    r.guard
        .write("rmu1_s2.Cmd", Value::Bool(true))
        .await
        .unwrap();
    // Information blocks nothing; do not operate blocks both ways.
    r.tags.replace(vec![
        tag(8, "rmu1_s3", TagKind::Information),
        tag(9, "rmu3_s2", TagKind::DoNotOperate),
    ]);
    r.guard
        .write("rmu1_s3.Cmd", Value::Bool(false))
        .await
        .unwrap();
    blocked(r.guard.write("rmu3_s2.Cmd", Value::Bool(false)).await);
}

#[tokio::test]
async fn two_closes_in_flight_cannot_together_parallel_grid_and_microgrid() {
    // RMU2's transformer breaker open: CSS1's LV side is dead. Closing the
    // PCC alone feeds it from the microgrid; closing RMU2 T alone feeds it
    // from the grid; both together parallel the two.
    let r = rig(&["rmu2_t"]);
    r.tags.replace(vec![]);
    assert!(r.guard.precheck("mg_pcc.Cmd", &Value::Bool(true)).is_ok());
    assert!(r.guard.precheck("rmu2_t.Cmd", &Value::Bool(true)).is_ok());
    let guard = r.guard.clone();
    let first = tokio::spawn(async move { guard.write("mg_pcc.Cmd", Value::Bool(true)).await });
    // Wait until the first is at the field (checked, counted as pending).
    while r.field.written.lock().unwrap().is_empty() {
        tokio::task::yield_now().await;
    }
    let b = blocked(r.guard.write("rmu2_t.Cmd", Value::Bool(true)).await);
    assert_eq!(b.rule, "forbidden_parallel", "{b}");
    let b = blocked(
        r.guard
            .precheck("rmu2_t.Cmd", &Value::Bool(true))
            .map(|_| unreachable!()),
    );
    assert_eq!(b.rule, "forbidden_parallel");
    r.field.gate.add_permits(1);
    first.await.unwrap().unwrap();
    assert_eq!(r.field.written.lock().unwrap().len(), 1);
}

#[tokio::test]
async fn an_interlock_refuses_on_the_write_path_too() {
    // C2 live: earthing it is refused, and nothing reaches the field.
    let r = rig(&[]);
    r.tags.replace(vec![]);
    r.field.gate.add_permits(10);
    let b = blocked(r.guard.write("rmu1_e2.Cmd", Value::Bool(true)).await);
    assert_eq!(b.rule, "earthing_energised", "{b}");
    assert!(r.field.written.lock().unwrap().is_empty());
    // C2 isolated at both ends: it may be earthed.
    let r = rig(&["rmu1_s2", "rmu2_s1"]);
    r.tags.replace(vec![]);
    r.field.gate.add_permits(10);
    r.guard
        .write("rmu1_e2.Cmd", Value::Bool(true))
        .await
        .unwrap();
}

#[tokio::test]
async fn a_selected_device_is_refused_to_every_other_command_until_the_selection_ends() {
    let r = rig(&[]);
    r.tags.replace(vec![]);
    r.field.gate.add_permits(10);
    let nop = r
        .guard
        .operation("rmu2_s2.Cmd", &Value::Bool(true))
        .unwrap()
        .0;
    let sel = r
        .selections
        .select(
            nop,
            "rmu2_s2",
            Operation::Close,
            "alice",
            Timestamp::from_millis(0),
        )
        .unwrap();
    let b = blocked(r.guard.write("rmu2_s2.Cmd", Value::Bool(true)).await);
    assert_eq!(b.rule, "reserved");
    assert!(b.reason.contains("alice"), "{b}");
    assert!(r.guard.precheck("rmu2_s2.Cmd", &Value::Bool(true)).is_err());
    // Other devices are free.
    r.guard
        .write("rmu1_s2.Cmd", Value::Bool(false))
        .await
        .unwrap();
    // The holder executes by ending the selection, then commanding.
    r.selections.take(sel.id).unwrap();
    r.guard
        .write("rmu2_s2.Cmd", Value::Bool(true))
        .await
        .unwrap();
}

#[tokio::test]
async fn an_overridden_selection_passes_the_overridable_rules_once() {
    // A disconnector feeding 30 customers: opening it under load is
    // refused, overridably.
    let model = Net::default()
        .source("grid", "a_bb", "grid")
        .switch("d1", SwitchKind::Disconnector, "a_bb", "b", true)
        .load("b_load", "b", 30)
        .build();
    let r = rig_of(model, &[]);
    r.tags.replace(vec![]);
    r.field.gate.add_permits(10);
    let b = blocked(r.guard.write("d1.Cmd", Value::Bool(false)).await);
    assert_eq!(b.rule, "disconnector_under_load");
    assert!(b.overridable);
    let d1 = r.guard.operation("d1.Cmd", &Value::Bool(false)).unwrap().0;
    // Granted for a close: the open is still refused.
    r.selections.grant(d1, Operation::Close);
    assert!(r.guard.precheck("d1.Cmd", &Value::Bool(false)).is_err());
    r.selections.grant(d1, Operation::Open);
    assert!(r.guard.precheck("d1.Cmd", &Value::Bool(false)).is_ok());
    r.guard.write("d1.Cmd", Value::Bool(false)).await.unwrap();
    assert!(
        !r.selections.granted(d1, Operation::Open),
        "used up by the command"
    );
    // A safety tag is never overridden.
    r.tags.replace(vec![tag(9, "d1", TagKind::DoNotOperate)]);
    r.selections.grant(d1, Operation::Close);
    let b = blocked(r.guard.write("d1.Cmd", Value::Bool(true)).await);
    assert_eq!(b.rule, "safety_tag");
}
