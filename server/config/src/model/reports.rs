//! `[reports]`: when the daily and monthly reports are made on their own
//! (into the data folder's `reports/`, `gridscada_reports`), and the
//! currency their costs are in.

use serde::{Deserialize, Serialize};
use serde_spanned::Spanned;

/// The report schedule. Without the section both reports are made, 15
/// minutes after their period ends (UTC).
#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct ReportsConfig {
    /// Make yesterday's report after each midnight (UTC).
    #[serde(default = "super::yes")]
    pub daily: bool,
    /// Make last month's report after the 1st of each month begins (UTC).
    #[serde(default = "super::yes")]
    pub monthly: bool,
    /// Minutes after the period's end before its report is made, so the
    /// historian's last samples of the period are written first (0 to 1440).
    #[serde(default = "default_delay")]
    pub delay_min: Spanned<f64>,
    /// The currency of the plant's prices (`cost_per_kwh`,
    /// `fuel_price_per_l`, `start_cost`...), as an ISO 4217 code (`EUR`):
    /// the report prints it beside every cost. Absent: costs are printed in
    /// "cost units", the prices' own unit, whatever it is.
    #[serde(default)]
    pub currency: Option<Spanned<String>>,
}

fn default_delay() -> Spanned<f64> {
    Spanned::new(0..0, 15.0)
}

impl Default for ReportsConfig {
    fn default() -> Self {
        ReportsConfig {
            daily: true,
            monthly: true,
            delay_min: default_delay(),
            currency: None,
        }
    }
}

impl ReportsConfig {
    /// The currency code, if one is configured.
    pub fn currency(&self) -> Option<&str> {
        self.currency.as_ref().map(|c| c.get_ref().as_str())
    }
}
