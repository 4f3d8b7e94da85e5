//! The `[profiles]` section: each zone's and unit's series, inline or
//! from a CSV file.

use std::path::Path;
use std::time::Duration;

use gridscada_config::SourceFile;
use serde_spanned::Spanned;
use toml::de::DeValue;

use crate::scenario::series::{parse_csv, Interpolate, Series};
use crate::scenario::{Profiles, ZoneProfile};

use super::names::{NameRef, RefKind};
use super::raw::{Interp, RawSeries};
use super::Parser;

impl Parser<'_> {
    pub(super) fn profiles(&mut self, value: &Spanned<DeValue<'_>>) -> Profiles {
        let mut out = Profiles::default();
        let Some(table) = value.get_ref().as_table() else {
            self.err(
                value.span(),
                "'profile' must be a table ([profile.demand] ...)",
            );
            return out;
        };
        for (key, v) in table.iter() {
            let k = key.get_ref().as_ref();
            let slot = match k {
                "irradiance" => &mut out.irradiance,
                "pv_available" => &mut out.pv_available,
                "wind_speed" => &mut out.wind_speed,
                "demand" => &mut out.demand,
                "zone" => {
                    for (raw, span) in self.each::<RawSeries>(v, "profile.zone") {
                        if let Some(z) = self.zone_profile(raw, span) {
                            out.zones.push(z);
                        }
                    }
                    continue;
                }
                other => {
                    self.err(
                        key.span(),
                        format!("unknown profile '{other}'; expected irradiance, pv_available, wind_speed, demand or [[profile.zone]]"),
                    );
                    continue;
                }
            };
            let label = format!("profile.{k}");
            let Some(raw) = self.de::<RawSeries>(v, &label) else {
                continue;
            };
            if raw.panel.is_some() || raw.zone.is_some() || raw.pf.is_some() {
                self.err(
                    v.span(),
                    format!("{label}: panel, zone and pf belong in [[profile.zone]]"),
                );
                continue;
            }
            self.refs.push(NameRef {
                kind: RefKind::Microgrid,
                name: k.to_string(),
                at: self.pos(key.span()),
            });
            *slot = self.series(raw, v.span(), &label);
        }
        if out.irradiance.is_some() && out.pv_available.is_some() {
            self.err(
                value.span(),
                "give either profile.irradiance or profile.pv_available, not both",
            );
        }
        out
    }

    fn zone_profile(
        &mut self,
        raw: RawSeries,
        span: std::ops::Range<usize>,
    ) -> Option<ZoneProfile> {
        let (Some(panel), Some(zone)) = (raw.panel.clone(), raw.zone.clone()) else {
            self.err(span, "[[profile.zone]] needs panel and zone");
            return None;
        };
        self.name_ref(RefKind::Panel, &panel);
        self.refs.push(NameRef {
            kind: RefKind::Zone(*zone.get_ref(), false),
            name: panel.get_ref().clone(),
            at: self.pos(zone.span()),
        });
        let pf = raw.pf.unwrap_or(0.9);
        if !(pf > 0.0 && pf <= 1.0) {
            self.err(span.clone(), "pf must be in (0, 1]");
        }
        let label = format!("zone profile {} zone {}", panel.get_ref(), zone.get_ref());
        let kw = self.series(raw, span, &label)?;
        Some(ZoneProfile {
            panel: panel.into_inner(),
            zone: zone.into_inner(),
            pf,
            kw,
        })
    }

    fn series(
        &mut self,
        raw: RawSeries,
        span: std::ops::Range<usize>,
        label: &str,
    ) -> Option<Series> {
        self.stream += 1;
        let sources = [
            raw.csv.is_some(),
            raw.points.is_some(),
            raw.constant.is_some(),
        ]
        .iter()
        .filter(|b| **b)
        .count();
        if sources != 1 {
            self.err(
                span,
                format!("{label}: give exactly one of csv, points or constant"),
            );
            return None;
        }
        let scale = raw.scale.unwrap_or(1.0);
        let noise = raw.noise.unwrap_or(0.0);
        if !(scale.is_finite() && (0.0..=1.0).contains(&noise)) {
            self.err(
                span.clone(),
                format!("{label}: scale must be finite and noise within 0..=1"),
            );
            return None;
        }
        let interpolate = match raw.interpolate {
            Some(Interp::Step) => Interpolate::Step,
            _ => Interpolate::Linear,
        };
        let (points, source) = if let Some(c) = raw.constant {
            if !c.is_finite() {
                self.err(span, format!("{label}: constant must be finite"));
                return None;
            }
            (vec![(Duration::ZERO, c)], format!("constant {c}"))
        } else if let Some(pts) = raw.points {
            let mut out = Vec::with_capacity(pts.len());
            for (t, v) in pts {
                match t.to_duration() {
                    Ok(d) => {
                        if out.last().is_some_and(|(p, _): &(Duration, f64)| *p >= d) {
                            self.err(
                                span.clone(),
                                format!("{label}: points must be in increasing time order"),
                            );
                            return None;
                        }
                        out.push((d, v));
                    }
                    Err(e) => {
                        self.err(span.clone(), format!("{label}: {e}"));
                        return None;
                    }
                }
            }
            if out.is_empty() {
                self.err(span, format!("{label}: points is empty"));
                return None;
            }
            (out, "points".to_string())
        } else {
            let csv = raw.csv?;
            let path = self.base.join(csv.get_ref());
            return self.csv_series(
                &csv,
                &path,
                raw.column.as_deref(),
                interpolate,
                scale,
                noise,
                label,
            );
        };
        Some(Series {
            points,
            interpolate,
            scale,
            noise,
            stream: self.stream,
            source,
        })
    }

    #[allow(clippy::too_many_arguments)]
    fn csv_series(
        &mut self,
        csv: &Spanned<String>,
        path: &Path,
        column: Option<&str>,
        interpolate: Interpolate,
        scale: f64,
        noise: f64,
        label: &str,
    ) -> Option<Series> {
        let text = match (self.read)(path) {
            Ok(t) => t,
            Err(e) => {
                self.err(
                    csv.span(),
                    format!("{label}: cannot read {}: {e}", path.display()),
                );
                return None;
            }
        };
        let f = SourceFile::new(path, text);
        let table = match parse_csv(&f) {
            Ok(t) => t,
            Err(d) => {
                self.diags.extend(d);
                return None;
            }
        };
        match table.column(column) {
            Ok(points) => Some(Series {
                points,
                interpolate,
                scale,
                noise,
                stream: self.stream,
                source: format!(
                    "{}:{}",
                    csv.get_ref(),
                    column.unwrap_or(table.columns.get(1).map(String::as_str).unwrap_or(""))
                ),
            }),
            Err(e) => {
                self.err(csv.span(), format!("{label}: {e}"));
                None
            }
        }
    }
}
