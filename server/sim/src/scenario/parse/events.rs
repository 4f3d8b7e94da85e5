//! One `[[event]]` entry: its time and the action it takes.

use serde_spanned::Spanned;

use crate::scenario::{Action, Event};
use crate::FaultKind;

use super::names::{NameRef, RefKind};
use super::raw::RawEvent;
use super::Parser;

impl Parser<'_> {
    pub(super) fn event(&mut self, raw: RawEvent, span: std::ops::Range<usize>) -> Option<Event> {
        let line = self.pos(span.clone()).0;
        let at = self.spanned_time(&raw.at, "at");
        let action_name = raw.action.get_ref().clone();
        // Which fields each action takes.
        let allowed: &[&str] = match action_name.as_str() {
            "fault" => &["panel", "zone", "kind"],
            "repair" => &["panel", "zone"],
            "mode" => &["panel", "mode", "user"],
            "reset" => &["panel", "user"],
            "breaker" => &["panel", "breaker", "close", "user"],
            "acknowledge" => &["user"],
            "comm_loss" | "comm_return" => &["device"],
            "trip" | "unit_reset" => &["unit"],
            "set_soc" => &["unit", "soc_pct"],
            other => {
                self.err(
                    raw.action.span(),
                    format!("unknown action '{other}'; expected fault, repair, mode, reset, breaker, acknowledge, comm_loss, comm_return, trip, unit_reset or set_soc"),
                );
                return None;
            }
        };
        let given: Vec<(&str, bool)> = vec![
            ("panel", raw.panel.is_some()),
            ("zone", raw.zone.is_some()),
            ("kind", raw.kind.is_some()),
            ("mode", raw.mode.is_some()),
            ("breaker", raw.breaker.is_some()),
            ("close", raw.close.is_some()),
            ("device", raw.device.is_some()),
            ("unit", raw.unit.is_some()),
            ("soc_pct", raw.soc_pct.is_some()),
            ("user", raw.user.is_some()),
        ];
        let mut ok = true;
        for (field, present) in &given {
            if *present && !allowed.contains(field) {
                self.err(
                    span.clone(),
                    format!("action '{action_name}' takes no '{field}'"),
                );
                ok = false;
            }
        }
        let mut need = |p: &mut Self, field: &str, present: bool| {
            if !present {
                p.err(
                    span.clone(),
                    format!("action '{action_name}' needs '{field}'"),
                );
                ok = false;
            }
        };
        let required: &[&str] = match action_name.as_str() {
            "fault" | "repair" => &["panel", "zone"],
            "mode" => &["panel", "mode"],
            "reset" => &["panel"],
            "breaker" => &["panel", "breaker", "close"],
            "comm_loss" | "comm_return" => &["device"],
            "trip" | "unit_reset" => &["unit"],
            "set_soc" => &["unit", "soc_pct"],
            _ => &[],
        };
        for f in required {
            let present = given.iter().any(|(g, p)| g == f && *p);
            need(self, f, present);
        }
        if !ok {
            return None;
        }
        let at = at?;
        let panel = raw.panel.clone();
        if let Some(p) = &panel {
            self.name_ref(RefKind::Panel, p);
        }
        let zone = |p: &mut Self, allow_zero: bool| -> u8 {
            let z = raw.zone.clone().expect("checked above");
            p.refs.push(NameRef {
                kind: RefKind::Zone(*z.get_ref(), allow_zero),
                name: panel
                    .as_ref()
                    .map(|x| x.get_ref().clone())
                    .unwrap_or_default(),
                at: p.pos(z.span()),
            });
            z.into_inner()
        };
        let name = |s: &Option<Spanned<String>>| {
            s.as_ref().map(|x| x.get_ref().clone()).unwrap_or_default()
        };
        let action = match action_name.as_str() {
            "fault" => Action::Fault {
                panel: name(&raw.panel),
                zone: zone(self, true),
                kind: raw.kind.unwrap_or(FaultKind::Permanent),
            },
            "repair" => Action::Repair {
                panel: name(&raw.panel),
                zone: zone(self, true),
            },
            "mode" => Action::Mode {
                panel: name(&raw.panel),
                mode: raw.mode?,
            },
            "reset" => Action::Reset {
                panel: name(&raw.panel),
            },
            "breaker" => {
                let b = raw.breaker.clone()?;
                self.refs.push(NameRef {
                    kind: RefKind::Breaker(b.get_ref().clone()),
                    name: name(&raw.panel),
                    at: self.pos(b.span()),
                });
                Action::Breaker {
                    panel: name(&raw.panel),
                    breaker: b.into_inner(),
                    close: raw.close?,
                }
            }
            "acknowledge" => Action::Acknowledge {
                user: raw.user.clone().unwrap_or_else(|| "operator".into()),
            },
            "comm_loss" | "comm_return" => {
                let d = raw.device.clone()?;
                self.name_ref(RefKind::Device, &d);
                if action_name == "comm_loss" {
                    Action::CommLoss {
                        device: d.into_inner(),
                    }
                } else {
                    Action::CommReturn {
                        device: d.into_inner(),
                    }
                }
            }
            "trip" | "unit_reset" | "set_soc" => {
                let u = raw.unit.clone()?;
                let kind = if action_name == "set_soc" {
                    RefKind::StorageUnit
                } else {
                    RefKind::Unit
                };
                self.name_ref(kind, &u);
                match action_name.as_str() {
                    "trip" => Action::Trip {
                        unit: u.into_inner(),
                    },
                    "unit_reset" => Action::UnitReset {
                        unit: u.into_inner(),
                    },
                    _ => {
                        let soc = raw.soc_pct?;
                        if !(0.0..=100.0).contains(&soc) {
                            self.err(span, "soc_pct must be within 0..=100");
                            return None;
                        }
                        Action::SetSoc {
                            unit: u.into_inner(),
                            soc_pct: soc,
                        }
                    }
                }
            }
            _ => return None,
        };
        Some(Event { at, action, line })
    }
}
