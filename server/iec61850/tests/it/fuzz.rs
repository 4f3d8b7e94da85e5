//! 200 000 mutated server packets (from the real captures) and random
//! octets through the upper layers, the MMS decoder and the ACSI decoders:
//! nothing panics. A deterministic xorshift keeps failures reproducible.

use std::time::{Duration, Instant};

use gridscada_iec61850::acsi::{LastApplError, Report};
use gridscada_iec61850::iso::{Addressing, Stack, TpktDecoder};
use gridscada_iec61850::mms::Pdu;

use super::fixtures::fixture;

const ROUNDS: usize = 200_000;

struct XorShift(u64);

impl XorShift {
    fn next(&mut self) -> u64 {
        let mut x = self.0;
        x ^= x << 13;
        x ^= x >> 7;
        x ^= x << 17;
        self.0 = x;
        x
    }
    fn below(&mut self, n: usize) -> usize {
        (self.next() % n.max(1) as u64) as usize
    }
}

fn decode_everything(stack: &mut Stack, packet: &[u8]) {
    let mut d = TpktDecoder::default();
    d.push(packet);
    while let Ok(Some(p)) = d.next_packet() {
        if let Ok(
            gridscada_iec61850::iso::Incoming::Mms(pdu)
            | gridscada_iec61850::iso::Incoming::Accepted(pdu),
        ) = stack.receive(&p)
        {
            if let Ok(Pdu::InformationReport(r)) = Pdu::decode(&pdu) {
                let _ = Report::decode(&r);
                let _ = LastApplError::from_report(&r);
            }
        }
    }
    // The MMS decoder on its own, on the raw octets too.
    let _ = Pdu::decode(packet);
}

#[test]
fn mutated_and_random_packets_never_panic() {
    let seeds: Vec<Vec<u8>> = [
        "associate.hex",
        "read.hex",
        "report.hex",
        "control.hex",
        "getnamelist.hex",
        "release.hex",
    ]
    .iter()
    .flat_map(|f| fixture(f))
    .filter(|(from_server, _)| *from_server)
    .map(|(_, p)| p)
    .collect();
    assert!(seeds.len() > 20);
    let mut rng = XorShift(0x6121_8505_0000_0001);
    let started = Instant::now();
    let mut stack = Stack::new(Addressing::default(), 1 << 16);
    for round in 0..ROUNDS {
        let mut p = seeds[rng.below(seeds.len())].clone();
        match round % 4 {
            0 => {
                for _ in 0..1 + rng.below(4) {
                    let i = rng.below(p.len());
                    p[i] ^= 1 << rng.below(8);
                }
            }
            1 => {
                let i = rng.below(p.len());
                p[i] = rng.next() as u8;
                let cut = rng.below(p.len() + 1);
                p.truncate(cut.max(4));
            }
            2 => {
                let i = 4 + rng.below(p.len().saturating_sub(4));
                if i < p.len() {
                    // A length octet lying.
                    p[i] = [0x00, 0x7f, 0x81, 0x82, 0x84, 0x85, 0xff][rng.below(7)];
                }
            }
            _ => {
                let n = rng.below(300);
                p = (0..n).map(|_| rng.next() as u8).collect();
                if n > 4 && rng.below(2) == 0 {
                    p[0] = 3;
                    p[1] = 0;
                    p[2] = 0;
                    p[3] = n as u8;
                }
            }
        }
        decode_everything(&mut stack, &p);
        if round % 1000 == 0 {
            stack = Stack::new(Addressing::default(), 1 << 16);
        }
    }
    assert!(
        started.elapsed() < Duration::from_secs(120),
        "the fuzz run took {:?}",
        started.elapsed()
    );
}
