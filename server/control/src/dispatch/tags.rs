//! The dispatch's derived tags: what the outer loop decided, as tags, so the
//! historian trends it and the HMI can show it like any other value.

use gridscada_tagdb::{Quality, Sample, TagDb, TagMeta, Timestamp, Value, ValueKind};

use super::{DispatchMode, DispatchStatus};

/// Prefix of the dispatch tags.
pub const PREFIX: &str = "MG.Dispatch";

/// The tags the application registers before building the tag database.
pub fn dispatch_tags() -> Vec<TagMeta> {
    let t = |name: &str, kind, units: &str, desc: &str| {
        TagMeta::new(format!("{PREFIX}.{name}"), kind)
            .units(units)
            .describe(desc)
    };
    vec![
        t(
            "Mode",
            ValueKind::Str,
            "",
            "Dispatch mode: optimal or fallback",
        ),
        t(
            "Status",
            ValueKind::Str,
            "",
            "Solver status of the last period",
        ),
        t(
            "Reason",
            ValueKind::Str,
            "",
            "Why the loop is in fallback, if it is",
        ),
        t("Objective", ValueKind::Float, "", "Cost of the last period"),
        t(
            "SolveMs",
            ValueKind::Float,
            "ms",
            "Solve time of the last period",
        ),
        t(
            "Shed_kW",
            ValueKind::Float,
            "kW",
            "Load shed in the last period",
        ),
        t(
            "Demand_kW",
            ValueKind::Float,
            "kW",
            "Demand the last period was solved for",
        ),
    ]
}

/// Writes `status` into the dispatch tags as one batch.
pub fn publish(db: &TagDb, status: &DispatchStatus, now: Timestamp) {
    let id = |name: &str| db.id(&format!("{PREFIX}.{name}"));
    let good = |v: Value| Sample {
        value: v,
        quality: Quality::GOOD,
        timestamp: now,
    };
    let number = |v: Option<f64>| match v {
        Some(x) if x.is_finite() => good(Value::Float(x)),
        _ => Sample {
            value: Value::Float(0.0),
            quality: Quality::bad("not solved"),
            timestamp: now,
        },
    };
    let mode = match status.mode {
        DispatchMode::Optimal => "optimal",
        DispatchMode::Fallback => "fallback",
    };
    let demand = status.inputs.as_ref().map(|p| p.demand_kw);
    let batch = [
        ("Mode", good(Value::from(mode))),
        ("Status", good(Value::from(status.status.as_str()))),
        (
            "Reason",
            good(Value::from(status.reason.as_deref().unwrap_or(""))),
        ),
        ("Objective", number(status.objective)),
        ("SolveMs", number(status.solve_ms)),
        ("Shed_kW", good(Value::Float(status.shed_kw))),
        ("Demand_kW", number(demand)),
    ];
    db.apply(batch.into_iter().filter_map(|(n, s)| id(n).map(|i| (i, s))));
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn publishes_every_tag() {
        let db = TagDb::new(dispatch_tags()).unwrap();
        let status = DispatchStatus {
            status: "optimal".into(),
            mode: DispatchMode::Optimal,
            objective: Some(12.5),
            solve_ms: Some(0.1),
            ..Default::default()
        };
        publish(&db, &status, Timestamp::from_millis(5));
        let s = db.get_by_name("MG.Dispatch.Objective").unwrap();
        assert_eq!(s.value, Value::Float(12.5));
        assert!(s.quality.is_good());
        assert_eq!(
            db.get_by_name("MG.Dispatch.Mode").unwrap().value,
            Value::from("optimal")
        );
        // No inputs yet: demand is not known.
        assert!(!db
            .get_by_name("MG.Dispatch.Demand_kW")
            .unwrap()
            .quality
            .is_good());
    }
}
