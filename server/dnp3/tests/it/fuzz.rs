//! 200 000 random and mutated inputs to every decoder, and to the master
//! as octets from the wire: nothing panics, and what decodes re-encodes.
//! A deterministic xorshift generator keeps failures reproducible.

use std::time::{Duration, Instant};

use gridscada_dnp3::app::{ObjectHeader, RequestHeader, ResponseHeader};
use gridscada_dnp3::link::{self, LinkFrame};
use gridscada_dnp3::master::{Command, CommandMode};
use gridscada_dnp3::objects::{self, Crob};
use gridscada_dnp3::transport::{self, Reassembler};
use gridscada_dnp3::{Action, Clock, CommandObject, Master, MasterConfig};

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
        (self.next() % n as u64) as usize
    }
    fn byte(&mut self) -> u8 {
        self.next() as u8
    }
}

fn hex(s: &str) -> Vec<u8> {
    s.split_whitespace()
        .map(|b| u8::from_str_radix(b, 16).unwrap())
        .collect()
}

/// Response fragments of real shapes to mutate.
fn fragments() -> Vec<Vec<u8>> {
    [
        "C1 81 00 00 01 02 00 00 02 01 81 05 1E 01 01 00 00 01 00 01 D2 04 00 00 21 FB FF FF FF 14 01 00 05 05 01 A0 86 01 00",
        "F0 82 96 08 33 01 07 01 40 42 0F 00 00 00 02 03 17 02 03 81 05 00 04 01 0A 00",
        "C0 81 00 00 01 01 00 00 09 05 02 0A 01 00 02 03 05 03 01 00 00 04 E4 02 50 01 00 07 07 00",
        "C0 81 00 00 0C 01 28 01 00 03 00 03 01 64 00 00 00 C8 00 00 00 02",
        "C0 81 00 00 29 04 17 01 05 00 00 00 00 00 00 F8 3F 7F 20 08 28 01 00 07 00 01 00 00 00 00 00 00 F8 3F 01 00 00 00 00 00",
        "C0 81 00 00 16 05 17 01 02 01 2A 00 00 00 01 02 03 04 05 06 32 01 07 01 01 02 03 04 05 06 34 02 07 01 10 00",
        "C0 81 00 00 0A 02 00 00 01 81 01 0B 02 17 01 00 81 01 00 00 00 00 00 2A 01 28 01 00 02 00 01 05 00 00 00 03 02 00 00 00 41 15 01 00 00 00 01 07 00 00 00",
        "C3 01 3C 02 06 3C 03 06 3C 04 06 3C 01 06",
    ]
    .iter()
    .map(|s| hex(s))
    .collect()
}

/// Link frames (outstation to master 1) carrying those fragments.
fn wire(fragment: &[u8], tseq: &mut u8) -> Vec<u8> {
    let mut out = Vec::new();
    for seg in transport::segment(fragment, tseq) {
        let f = LinkFrame {
            dir: false,
            ..LinkFrame::user_data(1, 1024, seg)
        };
        out.extend(f.encode().unwrap());
    }
    out
}

fn mutate(rng: &mut XorShift, base: &[u8]) -> Vec<u8> {
    let mut b = base.to_vec();
    match rng.below(6) {
        0 => (0..rng.below(300)).map(|_| rng.byte()).collect(),
        1 => {
            for _ in 0..=rng.below(4) {
                if !b.is_empty() {
                    let i = rng.below(b.len());
                    b[i] ^= 1 << rng.below(8);
                }
            }
            b
        }
        2 => {
            if !b.is_empty() {
                let i = rng.below(b.len());
                b[i] = rng.byte();
            }
            b
        }
        3 => {
            let n = rng.below(b.len() + 1);
            b.truncate(n);
            b
        }
        4 => {
            let i = rng.below(b.len() + 1);
            for _ in 0..=rng.below(8) {
                b.insert(i, rng.byte());
            }
            b
        }
        _ => {
            // Interesting values in a random place (lengths, counts, ranges).
            if !b.is_empty() {
                let i = rng.below(b.len());
                b[i] = [0x00, 0xFF, 0x7F, 0x80, 0x05, 0x64, 0x28, 0x17][rng.below(8)];
            }
            b
        }
    }
}

#[test]
fn decoders_never_panic() {
    let mut rng = XorShift(0x2545_F491_4F6C_DD1D);
    let frags = fragments();
    let mut tseq = 0;
    let wires: Vec<Vec<u8>> = frags.iter().map(|f| wire(f, &mut tseq)).collect();
    let mut reassembler = Reassembler::new(512);
    let mut decoded = 0usize;
    let mut measurements = 0usize;
    for round in 0..ROUNDS {
        // The link layer, with its contract: decoded frames re-encode to
        // the octets taken; errors discard 1..=len octets.
        let w = mutate(&mut rng, &wires[round % wires.len()]);
        let mut buf = &w[..];
        loop {
            match link::decode(buf) {
                Ok(None) => break,
                Ok(Some((f, n))) => {
                    assert_eq!(f.encode().unwrap(), buf[..n], "round {round}");
                    decoded += 1;
                    let _ = reassembler.push(&f.data);
                    buf = &buf[n..];
                }
                Err(e) => {
                    let d = e.discard();
                    assert!(d >= 1 && d <= buf.len(), "round {round}: {e} discard {d}");
                    let _ = e.to_string();
                    buf = &buf[d..];
                }
            }
        }
        // Transport segments of random shape.
        let seg = mutate(&mut rng, &frags[round % frags.len()]);
        if let Ok(Some(f)) = reassembler.push(&seg) {
            assert!(f.len() <= 512);
        }
        // Application headers and objects.
        let f = mutate(&mut rng, &frags[round % frags.len()]);
        let _ = RequestHeader::decode(&f);
        if let Ok(h) = ResponseHeader::decode(&f) {
            let mut b = Vec::new();
            h.encode(&mut b);
            assert_eq!(b, f[..4]);
        }
        for at in [0, 2, 4] {
            if let Ok((h, n)) = ObjectHeader::decode(&f, at) {
                let mut b = Vec::new();
                h.encode(&mut b);
                assert_eq!(b, f[at..at + n], "round {round}");
            }
        }
        let o = objects::parse(f.get(4..).unwrap_or(&[]), 4);
        measurements += o.measurements.len();
        if let Some(e) = &o.error {
            let _ = e.to_string();
        }
        for m in &o.measurements {
            let _ = m.flags.describe();
            let _ = m.flags.quality();
        }
    }
    // Most mutations break a CRC (which is the point of a CRC): some frames
    // survive (truncation keeps whole frames, insertion before the start).
    assert!(
        decoded > ROUNDS / 100,
        "some mutated frames stay valid ({decoded})"
    );
    assert!(
        measurements > ROUNDS,
        "and many objects readable ({measurements})"
    );
}

#[test]
fn the_master_takes_any_octets() {
    let mut rng = XorShift(0x9E37_79B9_7F4A_7C15);
    let frags = fragments();
    let start = Instant::now();
    let mut clock = Clock {
        mono: start,
        unix_ms: 1_700_000_000_000,
    };
    let mut master = Master::new(MasterConfig::default());
    let mut tseq = 0;
    let mut actions = 0usize;
    let mut delivered = 0usize;
    let mut outcomes = 0usize;
    let mut count = |a: Vec<Action>| {
        for a in &a {
            match a {
                Action::Measurements(m) => delivered += m.len(),
                Action::CommandOutcome { .. } => outcomes += 1,
                _ => {}
            }
        }
        a.len()
    };
    for round in 0..ROUNDS {
        if round % 5000 == 0 {
            master.disconnected();
            actions += count(master.connected(clock));
        }
        // Mostly well-framed mutated fragments (to reach the application
        // layer), sometimes mutated wire octets, sometimes pure noise.
        let f = &frags[rng.below(frags.len())];
        let mut f = mutate(&mut rng, f);
        if rng.below(4) == 0 && f.len() > 1 {
            // A plausible response to what is in flight.
            f[0] = (f[0] & 0xF0) | (rng.byte() & 0x0F);
        }
        let octets = match rng.below(10) {
            0 => mutate(&mut rng, &wire(&f, &mut tseq)),
            1 => (0..rng.below(64)).map(|_| rng.byte()).collect(),
            _ => wire(&f, &mut tseq),
        };
        actions += count(master.received(&octets, clock));
        if rng.below(50) == 0 {
            let object = CommandObject::Crob(Crob::latch(rng.below(2) == 0));
            actions += count(master.command(
                Command {
                    id: round as u64,
                    index: rng.below(8) as u16,
                    object,
                    mode: if rng.below(2) == 0 {
                        CommandMode::SelectBeforeOperate
                    } else {
                        CommandMode::DirectOperate
                    },
                },
                clock,
            ));
        }
        clock.mono += Duration::from_millis(rng.below(1500) as u64);
        clock.unix_ms += 700;
        actions += count(master.tick(clock));
    }
    assert!(actions > ROUNDS);
    eprintln!("{actions} actions, {delivered} measurements, {outcomes} command outcomes");
    assert!(
        delivered > ROUNDS / 20,
        "the fuzz reaches the objects ({delivered})"
    );
    assert!(outcomes > 100, "and the commands' procedures ({outcomes})");
}
