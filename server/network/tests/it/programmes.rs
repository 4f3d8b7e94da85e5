//! Switching programmes played forward on the demo ring: a programme that
//! takes cable C2 out for work and restores it has no refusal at any step;
//! the same steps in an impossible order are refused at the step that
//! breaks a rule, naming it; a programme naming unknown devices or kinds is
//! refused as written, every problem with its step.

use gridscada_network::programme::{check, parse, StepText};
use gridscada_network::*;

use crate::cases::ring;

fn op(device: &str, operation: &str) -> StepText {
    StepText::Operate {
        device: device.into(),
        operation: operation.into(),
    }
}

fn tag(device: &str) -> StepText {
    StepText::PlaceTag {
        device: device.into(),
        tag_kind: "do_not_close".into(),
        reason: "C2 out for jointing".into(),
        work_ref: "WO-7".into(),
    }
}

fn untag(device: &str) -> StepText {
    StepText::RemoveTag {
        device: device.into(),
        tag_kind: "do_not_close".into(),
    }
}

fn c2_out_and_back() -> Vec<StepText> {
    vec![
        op("rmu2_s2", "close"),
        op("rmu1_s2", "open"),
        op("rmu2_s1", "open"),
        tag("rmu1_s2"),
        tag("rmu2_s1"),
        op("rmu1_e2", "close"),
        op("rmu2_e2", "close"),
        StepText::Manual {
            text: "jointing done, permit cancelled".into(),
        },
        op("rmu1_e2", "open"),
        op("rmu2_e2", "open"),
        untag("rmu1_s2"),
        untag("rmu2_s1"),
        op("rmu2_s1", "close"),
        op("rmu1_s2", "close"),
        op("rmu2_s2", "open"),
    ]
}

#[test]
fn a_programme_taking_a_cable_out_and_back_is_clean_at_every_step() {
    let m = ring();
    let steps = parse(&m, &c2_out_and_back()).unwrap();
    let checks = check(&m, &Inputs::normal(&m), &[], &steps, 0);
    assert_eq!(checks.len(), steps.len());
    for (n, c) in checks.iter().enumerate() {
        assert!(c.refusals.is_empty(), "step {}: {:?}", n + 1, c.refusals);
    }
    // Closing NOP1 first: opening C2's ends takes no customer off supply.
    for n in [1, 2] {
        let e = checks[n].effect.as_ref().unwrap();
        assert_eq!(e.customers_lose, 0, "step {}", n + 1);
    }
    // The earth switches earth C2.
    let c2 = m.section("c2").unwrap();
    assert!(checks[5]
        .effect
        .as_ref()
        .unwrap()
        .newly_earthed
        .contains(&c2));
    // From the middle: the steps still to do, from the state now.
    let later = check(&m, &Inputs::normal(&m), &[], &steps, 12);
    assert_eq!(later.len(), 3);
}

#[test]
fn an_impossible_order_is_refused_at_the_step_that_breaks_a_rule() {
    let m = ring();
    // Earthing C2 before it is made dead.
    let mut texts = c2_out_and_back();
    texts.swap(1, 5);
    let steps = parse(&m, &texts).unwrap();
    let checks = check(&m, &Inputs::normal(&m), &[], &steps, 0);
    assert_eq!(checks[1].refusals[0].rule, RuleId::EarthingEnergised);
    // Closing onto the earthed cable: the tag refuses, and so does the rule.
    let texts = vec![
        op("rmu1_s2", "open"),
        op("rmu2_s1", "open"),
        tag("rmu1_s2"),
        op("rmu1_e2", "close"),
        op("rmu1_s2", "close"),
        untag("rmu2_s1"),
    ];
    let steps = parse(&m, &texts).unwrap();
    let checks = check(&m, &Inputs::normal(&m), &[], &steps, 0);
    let rules: Vec<RuleId> = checks[4].refusals.iter().map(|r| r.rule).collect();
    assert!(rules.contains(&RuleId::SafetyTag), "{rules:?}");
    assert!(rules.contains(&RuleId::ClosingOntoEarthed), "{rules:?}");
    // Removing a tag nothing placed.
    assert_eq!(checks[5].refusals[0].rule, RuleId::SafetyTag);
    assert!(checks[5].refusals[0].text.contains("no DO NOT CLOSE tag"));
    // A standing tag counts: the check starts from the tags as they are.
    let standing = SafetyTag {
        id: 1,
        device: "rmu2_s1".into(),
        kind: TagKind::DoNotClose,
        reason: "r".into(),
        work_ref: String::new(),
        placed_by: "alice".into(),
        placed_at: gridscada_tagdb::Timestamp::from_millis(0),
    };
    let checks = check(&m, &Inputs::normal(&m), &[standing], &steps, 0);
    assert!(checks[5].refusals.is_empty());
}

#[test]
fn a_programme_as_written_is_refused_with_every_problem_at_its_step() {
    let m = ring();
    let errors = parse(
        &m,
        &[
            op("f1", "open"),
            op("nope", "open"),
            op("f2", "toggle"),
            StepText::PlaceTag {
                device: "f1".into(),
                tag_kind: "maybe".into(),
                reason: " ".into(),
                work_ref: String::new(),
            },
            StepText::Manual { text: "".into() },
        ],
    )
    .unwrap_err();
    let all = errors.join("\n");
    for want in [
        "step 2: no switching device 'nope'",
        "step 3: operation 'toggle'",
        "step 4: tag kind 'maybe'",
        "step 4: a safety tag needs a reason",
        "step 5: a manual step needs its instruction",
    ] {
        assert!(all.contains(want), "missing {want:?} in\n{all}");
    }
    assert!(parse(&m, &[]).is_err());
}
