//! Alarm evaluation throughput: 100,000 analog alarms (25,000 tags with
//! HiHi/Hi/Lo/LoLo each) evaluated against changing values through the full
//! state machine (deadband, delays, transitions), next to a naive baseline
//! that only compares each value with its limits. Prints evaluations per
//! second for both.
//!
//! Run: `cargo run --release -p gridscada-alarms --example alarm_bench`

use std::time::{Duration, Instant};

use gridscada_alarms::{AlarmDef, AlarmKind, AlarmSet, Condition, Outputs};
use gridscada_tagdb::{Sample, Timestamp};

const TAGS: usize = 25_000;
const ROUNDS: usize = 40;

fn main() {
    let mut defs = Vec::with_capacity(TAGS * 4);
    for t in 0..TAGS {
        let tag = format!("BENCH.T{t}.V");
        for (kind, cond) in [
            (
                AlarmKind::HiHi,
                Condition::Above {
                    limit: 265.0,
                    deadband: 2.0,
                },
            ),
            (
                AlarmKind::Hi,
                Condition::Above {
                    limit: 253.0,
                    deadband: 2.0,
                },
            ),
            (
                AlarmKind::Lo,
                Condition::Below {
                    limit: 207.0,
                    deadband: 2.0,
                },
            ),
            (
                AlarmKind::LoLo,
                Condition::Below {
                    limit: 195.0,
                    deadband: 2.0,
                },
            ),
        ] {
            defs.push(AlarmDef {
                key: format!("{tag}:{kind}"),
                tag: Some(tag.clone()),
                kind,
                priority: 500,
                selection: "BENCH".into(),
                message: "{tag} {value} {units} (limit {limit})".into(),
                units: "V".into(),
                device: None,
                states: None,
                decimals: None,
                condition: cond,
                on_delay: Duration::from_secs(2),
                off_delay: Duration::ZERO,
            });
        }
    }
    let mut set = AlarmSet::new(defs, vec![]).expect("bench alarms are valid");
    let inputs: Vec<_> = set.inputs().map(|(id, _)| id).collect();
    println!(
        "{} alarms on {} tags, {} rounds of every tag changing",
        set.len(),
        inputs.len(),
        ROUNDS
    );

    // Values sweep through all bands so alarms activate, run delays and return.
    let value = |tag: usize, round: usize| -> f64 {
        let phase = (tag * 7 + round * 13) % 100;
        150.0 + phase as f64 * 1.4
    };

    let mut out = Outputs::default();
    let mut transitions = 0usize;
    let start = Instant::now();
    for round in 0..ROUNDS {
        let now = Timestamp::from_millis(round as i64 * 1000);
        let samples: Vec<Sample> = (0..inputs.len())
            .map(|t| Sample::good(value(t, round), now))
            .collect();
        let batch: Vec<_> = inputs.iter().copied().zip(samples.iter()).collect();
        set.apply(&batch, now, &mut out);
        set.tick(now, &mut out);
        transitions += out.transitions.len();
        out.clear();
    }
    let engine_time = start.elapsed();
    let evals = set.evaluations();
    let engine_rate = evals as f64 / engine_time.as_secs_f64();

    // Baseline: compare each value with the four limits, no state.
    let limits = [(265.0, true), (253.0, true), (207.0, false), (195.0, false)];
    let mut active = 0usize;
    let start = Instant::now();
    for round in 0..ROUNDS {
        let now = Timestamp::from_millis(round as i64 * 1000);
        let samples: Vec<Sample> = (0..inputs.len())
            .map(|t| Sample::good(value(t, round), now))
            .collect();
        for s in &samples {
            let v = s.value.as_f64().unwrap_or(f64::NAN);
            for (l, above) in limits {
                active += usize::from(if above { v > l } else { v < l });
            }
        }
    }
    let base_time = start.elapsed();
    let base_evals = (ROUNDS * inputs.len() * 4) as f64;
    let base_rate = base_evals / base_time.as_secs_f64();
    std::hint::black_box(active);

    println!(
        "state machine : {evals} evaluations in {:.3} s = {:.2} M evaluations/s ({transitions} transitions)",
        engine_time.as_secs_f64(),
        engine_rate / 1e6
    );
    println!(
        "naive baseline: {base_evals} comparisons in {:.3} s = {:.2} M evaluations/s",
        base_time.as_secs_f64(),
        base_rate / 1e6
    );
    println!(
        "state machine costs {:.1}x the naive loop per evaluation",
        base_rate / engine_rate.max(1e-9)
    );
}
