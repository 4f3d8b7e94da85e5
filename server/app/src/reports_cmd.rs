//! `gridscada report PERIOD`: one report made now from the database, into
//! the data folder's `reports/`, as the schedule makes them.

use anyhow::Context;
use gridscada_reports::{Archive, Period};
use gridscada_tagdb::Timestamp;

use crate::users::{open_with_plant, Target};

pub async fn run(period: String, target: Target) -> anyhow::Result<()> {
    let period = Period::parse(&period)?;
    let (store, plant, data) = open_with_plant(target).await?;
    let report = gridscada_reports::generate(&store, &plant, period, Timestamp::now_utc())
        .await
        .with_context(|| format!("making the report of {period}"))?;
    let archive = Archive::in_data_dir(&data);
    archive
        .save(&report)
        .with_context(|| format!("writing the report into {}", archive.dir().display()))?;
    for f in gridscada_reports::archive::FORMATS {
        println!("{}", archive.path(period, f).display());
    }
    store.close().await;
    Ok(())
}
