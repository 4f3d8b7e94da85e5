//! `[hmi]`: how the HMI shows numbers and dates plant-wide. A tag's own
//! `decimals` (in `tags.rs`) overrides the plant's.

use gridscada_tagdb::ValueKind;
use serde::{Deserialize, Serialize};
use serde_spanned::Spanned;

#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct HmiConfig {
    /// Decimals of an analog value whose tag sets none, so one screen's
    /// numbers line up (0 to [`MAX_DECIMALS`]; read as any integer so that
    /// one out of range is reported by name).
    #[serde(default = "default_decimals")]
    pub decimals: Spanned<i64>,
    /// The order of a date's parts; times are always 24-hour.
    #[serde(default = "default_date_format")]
    pub date_format: Spanned<DateFormat>,
}

impl Default for HmiConfig {
    fn default() -> Self {
        HmiConfig {
            decimals: default_decimals(),
            date_format: default_date_format(),
        }
    }
}

/// The most decimals a value is shown with: a field value is not more exact.
pub const MAX_DECIMALS: u8 = 6;

/// The plant-wide decimals when `[hmi]` sets none.
pub const DEFAULT_DECIMALS: u8 = 1;

fn default_decimals() -> Spanned<i64> {
    Spanned::new(0..0, DEFAULT_DECIMALS.into())
}
fn default_date_format() -> Spanned<DateFormat> {
    Spanned::new(0..0, DateFormat::default())
}

/// How a date is written, named by its pattern.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Deserialize, Serialize)]
pub enum DateFormat {
    /// ISO 8601, 2026-11-21: sorts as text.
    #[default]
    #[serde(rename = "YYYY-MM-DD")]
    Iso,
    /// 21.11.2026
    #[serde(rename = "DD.MM.YYYY")]
    DayDotted,
    /// 21/11/2026
    #[serde(rename = "DD/MM/YYYY")]
    DaySlashed,
    /// 11/21/2026
    #[serde(rename = "MM/DD/YYYY")]
    MonthSlashed,
}

impl DateFormat {
    /// The pattern as configured, which the HMI formats by.
    pub fn pattern(self) -> &'static str {
        match self {
            DateFormat::Iso => "YYYY-MM-DD",
            DateFormat::DayDotted => "DD.MM.YYYY",
            DateFormat::DaySlashed => "DD/MM/YYYY",
            DateFormat::MonthSlashed => "MM/DD/YYYY",
        }
    }
}

impl HmiConfig {
    /// The plant's decimals (`check` refuses one out of range).
    pub fn decimals(&self) -> u8 {
        u8::try_from(*self.decimals.get_ref()).unwrap_or(DEFAULT_DECIMALS)
    }

    /// The decimals a value of `kind` is shown with: the tag's `own`, else
    /// none for an integer and the plant's for an analog value; `None` for
    /// what is not a number (a bool, a text), which is shown in words.
    pub fn decimals_for(&self, kind: ValueKind, own: Option<u8>) -> Option<u8> {
        match kind {
            ValueKind::Int => Some(own.unwrap_or(0)),
            ValueKind::Float => Some(own.unwrap_or(self.decimals())),
            _ => None,
        }
    }
}
