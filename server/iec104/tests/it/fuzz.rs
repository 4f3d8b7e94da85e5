//! A deterministic fuzz loop (xorshift, no proptest in the lock file): 200k
//! random and mutated frames through both decoders. Neither may panic, and
//! whatever decodes must re-encode to octets that decode equal.

use crate::common;

use common::sample_asdus;
use gridscada_iec104::{apci, Asdu, Frame};

const ROUNDS: usize = 200_000;

/// xorshift64*: small, fast and the same on every machine.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }
    fn below(&mut self, n: usize) -> usize {
        (self.next() % n as u64) as usize
    }
    fn byte(&mut self) -> u8 {
        self.next() as u8
    }
}

/// Valid APDUs to mutate: every sample ASDU in an I frame, S and U frames.
fn corpus() -> Vec<Vec<u8>> {
    let mut out: Vec<Vec<u8>> = sample_asdus()
        .iter()
        .enumerate()
        .map(|(i, a)| {
            apci::encode(&Frame::I {
                send_seq: i as u16,
                recv_seq: 32767 - i as u16,
                asdu: a.encode(),
            })
            .unwrap()
        })
        .collect();
    out.push(apci::encode(&Frame::S { recv_seq: 12345 }).unwrap());
    out.push(common::hex("68 04 07 00 00 00"));
    out.push(common::hex("68 04 83 00 00 00"));
    out
}

fn mutate(rng: &mut Rng, base: &[u8]) -> Vec<u8> {
    let mut b = base.to_vec();
    for _ in 0..1 + rng.below(4) {
        match rng.below(8) {
            // Flip a bit, mostly in the ASDU so that many still decode.
            0..=2 if !b.is_empty() => {
                let i = rng.below(b.len());
                b[i] ^= 1 << rng.below(8);
            }
            3 if !b.is_empty() => {
                let i = rng.below(b.len());
                b[i] = rng.byte();
            }
            4 if !b.is_empty() => b.truncate(rng.below(b.len())),
            5 => {
                for _ in 0..rng.below(12) {
                    b.push(rng.byte());
                }
            }
            // Keep the length octet honest after a change, so the ASDU
            // decoder sees the damage rather than the framing.
            6 if b.len() >= 2 => b[1] = (b.len() - 2).min(255) as u8,
            _ if b.len() > 7 => {
                // Change the object count or SQ bit.
                b[7] = rng.byte();
            }
            _ => {}
        }
    }
    b
}

fn random(rng: &mut Rng) -> Vec<u8> {
    let n = rng.below(300);
    let mut b: Vec<u8> = (0..n).map(|_| rng.byte()).collect();
    if n >= 2 && rng.below(2) == 0 {
        b[0] = 0x68;
        b[1] = (n - 2).min(255) as u8;
    }
    b
}

/// Decoded ASDUs must re-encode to octets that decode equal (compared by
/// `Debug`, since a NaN float is not equal to itself but keeps its bits).
fn check_asdu(bytes: &[u8]) -> bool {
    let Ok(a) = Asdu::decode(bytes) else {
        return false;
    };
    let again = a.encode();
    assert!(again.len() <= apci::MAX_ASDU_LEN);
    let b = Asdu::decode(&again).unwrap_or_else(|e| panic!("re-encoded ASDU fails: {e}"));
    assert_eq!(format!("{a:?}"), format!("{b:?}"));
    assert_eq!(b.encode(), again);
    true
}

#[test]
fn no_panic_and_decoded_frames_re_encode() {
    let corpus = corpus();
    let mut rng = Rng(0x9E37_79B9_7F4A_7C15);
    let (mut frames, mut asdus, mut needs_more, mut errors) = (0, 0, 0, 0);
    for round in 0..ROUNDS {
        let buf = if round % 4 == 0 {
            random(&mut rng)
        } else {
            let pick = rng.below(corpus.len());
            mutate(&mut rng, &corpus[pick])
        };
        match apci::decode(&buf) {
            Ok(Some((frame, used))) => {
                frames += 1;
                assert!(used <= buf.len());
                // The APCI decoder is strict, so the octets come back exactly.
                assert_eq!(apci::encode(&frame).unwrap(), buf[..used]);
                if let Frame::I { asdu, .. } = &frame {
                    asdus += usize::from(check_asdu(asdu));
                }
            }
            Ok(None) => {
                needs_more += 1;
                assert!(buf.len() < 2 + usize::from(buf.get(1).copied().unwrap_or(255)));
            }
            Err(e) => {
                errors += 1;
                assert!(!e.to_string().is_empty());
            }
        }
        // The ASDU decoder on its own, from the same octets at a few offsets.
        for skip in [0, 6, 1 + rng.below(8)] {
            if let Some(rest) = buf.get(skip..) {
                asdus += usize::from(check_asdu(rest));
            }
        }
    }
    eprintln!("frames {frames}, asdus {asdus}, incomplete {needs_more}, errors {errors}");
    // The fuzzer reached every verdict often enough to mean something.
    assert!(frames > 20_000, "{frames} frames decoded");
    assert!(asdus > 10_000, "{asdus} ASDUs decoded");
    assert!(needs_more > 1_000, "{needs_more} incomplete");
    assert!(errors > 10_000, "{errors} errors");
}

#[test]
fn byte_at_a_time_streaming_matches_whole_decoding() {
    let corpus = corpus();
    let stream: Vec<u8> = corpus.concat();
    let mut buf = Vec::new();
    let mut got = Vec::new();
    for &byte in &stream {
        buf.push(byte);
        if let Some((frame, used)) = apci::decode(&buf).unwrap() {
            got.push(frame);
            buf.drain(..used);
        }
    }
    assert!(buf.is_empty());
    assert_eq!(got.len(), corpus.len());
    for (frame, bytes) in got.iter().zip(&corpus) {
        assert_eq!(&apci::encode(frame).unwrap(), bytes);
    }
}
