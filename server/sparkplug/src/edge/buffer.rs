//! The store-and-forward buffer: while the broker is unreachable, the
//! samples that would have been published are appended to a file in the
//! data folder (`mqtt-buffer/samples.bin`, length-delimited Sparkplug
//! metrics with their tag names), up to a bound; later ones are dropped and
//! counted. On reconnect they are read back in order and sent as historical
//! data; a buffer left by a stop or a crash is sent after the next start.
//!
//! Dropping the newest rather than the oldest keeps the record gap-free from
//! the start of the outage; the present state is never lost either, since
//! the births after a reconnect carry every tag's current sample.

use std::fs::{File, OpenOptions};
use std::io::{self, BufWriter, Read, Write};
use std::path::{Path, PathBuf};

use prost::Message;

use crate::proto::Metric;

pub const BUFFER_FILE: &str = "samples.bin";

/// The on-disk buffer. Appends are written through at each [`flush`].
pub struct SampleBuffer {
    path: PathBuf,
    capacity: usize,
    len: usize,
    out: Option<BufWriter<File>>,
}

/// What reading a buffer file found.
#[derive(Debug, Default)]
pub struct Replay {
    pub metrics: Vec<Metric>,
    /// A torn or undecodable record at the end (a crash mid-write): cut off.
    pub torn_bytes: usize,
}

impl SampleBuffer {
    /// Opens (creating the folder) the buffer in `dir`, holding at most
    /// `capacity` samples. What an earlier run left is counted in `len`.
    pub fn open(dir: &Path, capacity: usize) -> io::Result<SampleBuffer> {
        std::fs::create_dir_all(dir)?;
        let path = dir.join(BUFFER_FILE);
        let len = if path.exists() {
            read_file(&path)?.metrics.len()
        } else {
            0
        };
        Ok(SampleBuffer {
            path,
            capacity,
            len,
            out: None,
        })
    }

    /// Samples held.
    pub fn len(&self) -> usize {
        self.len
    }

    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Appends `metric` if there is room; returns false (dropped) if full.
    pub fn push(&mut self, metric: &Metric) -> io::Result<bool> {
        if self.len >= self.capacity {
            return Ok(false);
        }
        if self.out.is_none() {
            let file = OpenOptions::new()
                .create(true)
                .append(true)
                .open(&self.path)?;
            self.out = Some(BufWriter::new(file));
        }
        let out = self.out.as_mut().expect("opened above");
        out.write_all(&metric.encode_length_delimited_to_vec())?;
        self.len += 1;
        Ok(true)
    }

    /// Writes what was appended through to the file.
    pub fn flush(&mut self) -> io::Result<()> {
        if let Some(out) = self.out.as_mut() {
            out.flush()?;
        }
        Ok(())
    }

    /// Takes every buffered sample, oldest first, and empties the buffer.
    /// A torn record at the end is reported and cut off.
    pub fn take(&mut self) -> io::Result<Replay> {
        self.flush()?;
        self.out = None;
        if !self.path.exists() {
            self.len = 0;
            return Ok(Replay::default());
        }
        let replay = read_file(&self.path)?;
        std::fs::remove_file(&self.path)?;
        self.len = 0;
        Ok(replay)
    }

    /// Puts back samples that could not be sent (the session ended during
    /// the replay), ahead of anything appended since.
    pub fn put_back(&mut self, metrics: &[Metric]) -> io::Result<()> {
        self.flush()?;
        self.out = None;
        let newer = if self.path.exists() {
            read_file(&self.path)?.metrics
        } else {
            Vec::new()
        };
        let tmp = self.path.with_extension("tmp");
        {
            let mut w = BufWriter::new(File::create(&tmp)?);
            for m in metrics.iter().chain(&newer) {
                w.write_all(&m.encode_length_delimited_to_vec())?;
            }
            w.flush()?;
            w.get_ref().sync_all()?;
        }
        std::fs::rename(&tmp, &self.path)?;
        self.len = metrics.len() + newer.len();
        Ok(())
    }
}

fn read_file(path: &Path) -> io::Result<Replay> {
    let mut bytes = Vec::new();
    File::open(path)?.read_to_end(&mut bytes)?;
    let mut rest = bytes.as_slice();
    let mut replay = Replay::default();
    while !rest.is_empty() {
        let before = rest;
        match Metric::decode_length_delimited(&mut rest) {
            Ok(m) => replay.metrics.push(m),
            Err(_) => {
                replay.torn_bytes = before.len();
                tracing::warn!(
                    file = %path.display(),
                    bytes = before.len(),
                    "the MQTT buffer ends in a torn record (a crash while writing it): cut off"
                );
                break;
            }
        }
    }
    Ok(replay)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn metric(i: u64) -> Metric {
        Metric {
            name: Some(format!("T{i}")),
            alias: Some(i),
            timestamp: Some(1000 + i),
            ..Default::default()
        }
    }

    #[test]
    fn the_buffer_is_bounded_and_replays_in_order() {
        let dir = tempfile::tempdir().unwrap();
        let mut b = SampleBuffer::open(dir.path(), 3).unwrap();
        for i in 0..5 {
            let kept = b.push(&metric(i)).unwrap();
            assert_eq!(kept, i < 3, "sample {i}");
        }
        b.flush().unwrap();
        assert_eq!(b.len(), 3);
        // A restart finds what was left.
        let mut again = SampleBuffer::open(dir.path(), 3).unwrap();
        assert_eq!(again.len(), 3);
        let r = again.take().unwrap();
        let order: Vec<u64> = r.metrics.iter().map(|m| m.alias.unwrap()).collect();
        assert_eq!(order, [0, 1, 2]);
        assert!(again.is_empty());
        assert!(again.take().unwrap().metrics.is_empty());
    }

    #[test]
    fn unsent_samples_go_back_ahead_of_newer_ones() {
        let dir = tempfile::tempdir().unwrap();
        let mut b = SampleBuffer::open(dir.path(), 10).unwrap();
        b.push(&metric(5)).unwrap();
        b.put_back(&[metric(1), metric(2)]).unwrap();
        let order: Vec<u64> = b
            .take()
            .unwrap()
            .metrics
            .iter()
            .map(|m| m.alias.unwrap())
            .collect();
        assert_eq!(order, [1, 2, 5]);
    }

    #[test]
    fn a_torn_last_record_is_cut_off() {
        let dir = tempfile::tempdir().unwrap();
        let mut b = SampleBuffer::open(dir.path(), 10).unwrap();
        b.push(&metric(1)).unwrap();
        b.push(&metric(2)).unwrap();
        b.flush().unwrap();
        let path = dir.path().join(BUFFER_FILE);
        let mut bytes = std::fs::read(&path).unwrap();
        bytes.truncate(bytes.len() - 3);
        std::fs::write(&path, bytes).unwrap();
        let mut b = SampleBuffer::open(dir.path(), 10).unwrap();
        let r = b.take().unwrap();
        assert_eq!(r.metrics.len(), 1);
        assert!(r.torn_bytes > 0);
    }
}
