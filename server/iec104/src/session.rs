//! The APCI procedures of one IEC 104 connection, either side: send and
//! receive sequence numbers, the `k` window of unacknowledged I-frames we
//! sent, acknowledging at the latest after `w` received I-frames or `t2`,
//! test frames after `t3` of silence, and `t1` on everything the peer owes
//! us. Pure: the caller feeds it frames and the time, and sends what it
//! asks for; a `Err` is a reason to close the connection.

use std::collections::VecDeque;
use std::time::{Duration, Instant};

use crate::apci::{seq_ack_valid, seq_add, seq_distance, Frame, UFunction};

/// `k`, `w` and the timers, from the configuration.
#[derive(Debug, Clone, Copy)]
pub struct Parameters {
    pub k: u16,
    pub w: u16,
    pub t1: Duration,
    pub t2: Duration,
    pub t3: Duration,
}

impl Default for Parameters {
    /// The standard's defaults.
    fn default() -> Self {
        Parameters {
            k: 12,
            w: 8,
            t1: Duration::from_secs(15),
            t2: Duration::from_secs(10),
            t3: Duration::from_secs(20),
        }
    }
}

/// Why a connection must close.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum SessionError {
    #[error("t1 expired: no acknowledgement of our I-frame {0} within t1")]
    AckTimeout(u16),
    #[error("t1 expired: no confirmation of {0} within t1")]
    ConfirmTimeout(&'static str),
    #[error("the peer acknowledged N(R) = {recv_seq}, outside the frames outstanding ({oldest}..={next})")]
    BadAck {
        recv_seq: u16,
        oldest: u16,
        next: u16,
    },
    #[error("the peer's I-frame has N(S) = {got}, expected {expected}")]
    Sequence { got: u16, expected: u16 },
    #[error("an I-frame arrived before data transfer was started")]
    NotStarted,
}

/// One connection's APCI state.
#[derive(Debug)]
pub struct Session {
    p: Parameters,
    /// V(S): the N(S) of our next I-frame.
    send_seq: u16,
    /// V(R): the N(S) we expect of the peer's next I-frame.
    recv_seq: u16,
    /// Our I-frames not yet acknowledged: N(S) and when sent (for t1).
    unacked: VecDeque<(u16, Instant)>,
    /// Peer I-frames received since we last acknowledged, and when the
    /// first of them arrived (for t2).
    to_ack: u16,
    to_ack_since: Option<Instant>,
    /// A U-frame activation we sent and its confirmation is owed (t1).
    pending_u: Option<(UFunction, Instant)>,
    /// Anything received, for t3.
    last_rx: Instant,
    /// Whether data transfer is started (STARTDT confirmed, or, on the
    /// controlled side, activated).
    started: bool,
}

/// What the caller must do after feeding the session.
#[derive(Debug, Default, PartialEq)]
pub struct Actions {
    /// Frames to send now, in order.
    pub send: Vec<Frame>,
    /// The ASDUs of I-frames received, in order.
    pub asdus: Vec<Vec<u8>>,
    /// A U-frame confirmation that arrived (STARTDT con, STOPDT con, TESTFR con).
    pub confirmed: Option<UFunction>,
    /// An activation from the peer (the controlled side's STARTDT act, STOPDT act).
    pub activated: Option<UFunction>,
}

impl Session {
    pub fn new(p: Parameters, now: Instant) -> Session {
        Session {
            p,
            send_seq: 0,
            recv_seq: 0,
            unacked: VecDeque::new(),
            to_ack: 0,
            to_ack_since: None,
            pending_u: None,
            last_rx: now,
            started: false,
        }
    }

    pub fn is_started(&self) -> bool {
        self.started
    }

    /// Whether another I-frame may be sent without exceeding `k`.
    pub fn can_send(&self) -> bool {
        self.started && self.unacked.len() < usize::from(self.p.k)
    }

    /// A U-frame activation (STARTDT, STOPDT or TESTFR act) to send; its
    /// confirmation is then owed within t1.
    pub fn activate(&mut self, f: UFunction, now: Instant) -> Frame {
        self.pending_u = Some((f, now));
        Frame::U(f)
    }

    /// Marks data transfer started on the controlled side, once it has
    /// confirmed the peer's STARTDT act.
    pub fn set_started(&mut self, started: bool) {
        self.started = started;
    }

    /// The I-frame that carries `asdu`, acknowledging what we received.
    /// The caller checks [`can_send`](Self::can_send) first.
    pub fn send_i(&mut self, asdu: Vec<u8>, now: Instant) -> Frame {
        let f = Frame::I {
            send_seq: self.send_seq,
            recv_seq: self.recv_seq,
            asdu,
        };
        self.unacked.push_back((self.send_seq, now));
        self.send_seq = seq_add(self.send_seq, 1);
        // An I-frame acknowledges too.
        self.to_ack = 0;
        self.to_ack_since = None;
        f
    }

    /// Takes one received frame.
    pub fn receive(&mut self, frame: Frame, now: Instant) -> Result<Actions, SessionError> {
        self.last_rx = now;
        let mut out = Actions::default();
        match frame {
            Frame::I {
                send_seq,
                recv_seq,
                asdu,
            } => {
                if !self.started {
                    return Err(SessionError::NotStarted);
                }
                if send_seq != self.recv_seq {
                    return Err(SessionError::Sequence {
                        got: send_seq,
                        expected: self.recv_seq,
                    });
                }
                self.acknowledged(recv_seq)?;
                self.recv_seq = seq_add(self.recv_seq, 1);
                self.to_ack += 1;
                self.to_ack_since.get_or_insert(now);
                if self.to_ack >= self.p.w {
                    out.send.push(self.ack());
                }
                out.asdus.push(asdu);
            }
            Frame::S { recv_seq } => self.acknowledged(recv_seq)?,
            Frame::U(f) => match f {
                UFunction::TestFrAct => out.send.push(Frame::U(UFunction::TestFrCon)),
                UFunction::StartDtAct | UFunction::StopDtAct => out.activated = Some(f),
                UFunction::StartDtCon | UFunction::StopDtCon | UFunction::TestFrCon => {
                    // A confirmation of what we activated: t1 stops.
                    if self
                        .pending_u
                        .is_some_and(|(sent, _)| sent.confirmation() == Some(f))
                    {
                        self.pending_u = None;
                    }
                    match f {
                        UFunction::StartDtCon => self.started = true,
                        UFunction::StopDtCon => self.started = false,
                        _ => {}
                    }
                    out.confirmed = Some(f);
                }
            },
        }
        Ok(out)
    }

    /// The time: acknowledgements owed (t2), test frames (t3), and what
    /// the peer owes us (t1).
    pub fn tick(&mut self, now: Instant) -> Result<Vec<Frame>, SessionError> {
        if let Some(&(seq, sent)) = self.unacked.front() {
            if now.duration_since(sent) >= self.p.t1 {
                return Err(SessionError::AckTimeout(seq));
            }
        }
        if let Some((f, sent)) = self.pending_u {
            if now.duration_since(sent) >= self.p.t1 {
                return Err(SessionError::ConfirmTimeout(f.name()));
            }
        }
        let mut send = Vec::new();
        if self
            .to_ack_since
            .is_some_and(|since| now.duration_since(since) >= self.p.t2)
        {
            send.push(self.ack());
        }
        if self.pending_u.is_none() && now.duration_since(self.last_rx) >= self.p.t3 {
            send.push(self.activate(UFunction::TestFrAct, now));
        }
        Ok(send)
    }

    /// When [`tick`](Self::tick) next has something to do.
    pub fn next_deadline(&self) -> Instant {
        let mut at = self.last_rx + self.p.t3;
        if let Some(&(_, sent)) = self.unacked.front() {
            at = at.min(sent + self.p.t1);
        }
        if let Some((_, sent)) = self.pending_u {
            at = at.min(sent + self.p.t1);
        }
        if let Some(since) = self.to_ack_since {
            at = at.min(since + self.p.t2);
        }
        at
    }

    fn ack(&mut self) -> Frame {
        self.to_ack = 0;
        self.to_ack_since = None;
        Frame::S {
            recv_seq: self.recv_seq,
        }
    }

    /// The peer acknowledged our I-frames up to `recv_seq` - 1.
    fn acknowledged(&mut self, recv_seq: u16) -> Result<(), SessionError> {
        let oldest = self
            .unacked
            .front()
            .map(|(s, _)| *s)
            .unwrap_or(self.send_seq);
        if !seq_ack_valid(recv_seq, oldest, self.send_seq) {
            return Err(SessionError::BadAck {
                recv_seq,
                oldest,
                next: self.send_seq,
            });
        }
        let n = seq_distance(oldest, recv_seq);
        for _ in 0..n {
            self.unacked.pop_front();
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn p() -> Parameters {
        Parameters {
            k: 3,
            w: 2,
            ..Parameters::default()
        }
    }

    fn started(now: Instant) -> Session {
        let mut s = Session::new(p(), now);
        s.activate(UFunction::StartDtAct, now);
        s.receive(Frame::U(UFunction::StartDtCon), now).unwrap();
        assert!(s.is_started());
        s
    }

    fn i(send_seq: u16, recv_seq: u16) -> Frame {
        Frame::I {
            send_seq,
            recv_seq,
            asdu: vec![1],
        }
    }

    #[test]
    fn the_k_window_closes_and_reopens_on_acknowledgement() {
        let t = Instant::now();
        let mut s = started(t);
        for _ in 0..3 {
            assert!(s.can_send());
            s.send_i(vec![1], t);
        }
        assert!(!s.can_send(), "k = 3 frames outstanding");
        s.receive(Frame::S { recv_seq: 2 }, t).unwrap();
        assert!(s.can_send());
        // An acknowledgement of frames never sent closes the connection.
        let e = s.receive(Frame::S { recv_seq: 7 }, t).unwrap_err();
        assert!(matches!(e, SessionError::BadAck { recv_seq: 7, .. }), "{e}");
    }

    #[test]
    fn received_frames_are_acknowledged_after_w_or_t2() {
        let t = Instant::now();
        let mut s = started(t);
        let a = s.receive(i(0, 0), t).unwrap();
        assert!(a.send.is_empty());
        assert_eq!(a.asdus.len(), 1);
        let a = s.receive(i(1, 0), t).unwrap();
        assert_eq!(a.send, vec![Frame::S { recv_seq: 2 }], "w = 2");
        s.receive(i(2, 0), t).unwrap();
        assert!(s.tick(t + Duration::from_secs(1)).unwrap().is_empty());
        let later = t + Duration::from_secs(10);
        assert_eq!(s.next_deadline(), later);
        assert_eq!(s.tick(later).unwrap(), vec![Frame::S { recv_seq: 3 }]);
        // Out of sequence: the connection closes.
        let e = s.receive(i(9, 0), later).unwrap_err();
        assert_eq!(
            e,
            SessionError::Sequence {
                got: 9,
                expected: 3
            }
        );
    }

    #[test]
    fn silence_brings_a_test_frame_and_no_answer_closes() {
        let t = Instant::now();
        let mut s = started(t);
        let t3 = t + Duration::from_secs(20);
        assert_eq!(s.tick(t3).unwrap(), vec![Frame::U(UFunction::TestFrAct)]);
        assert!(s.tick(t3 + Duration::from_secs(5)).unwrap().is_empty());
        let e = s.tick(t3 + Duration::from_secs(15)).unwrap_err();
        assert_eq!(e, SessionError::ConfirmTimeout("TESTFR act"));
        // Answered in time, the link lives on.
        let mut s = started(t);
        s.tick(t3).unwrap();
        s.receive(Frame::U(UFunction::TestFrCon), t3 + Duration::from_secs(1))
            .unwrap();
        assert!(s.tick(t3 + Duration::from_secs(15)).unwrap().is_empty());
    }

    #[test]
    fn an_unacknowledged_frame_expires_t1() {
        let t = Instant::now();
        let mut s = started(t);
        s.send_i(vec![1], t);
        let e = s.tick(t + Duration::from_secs(15)).unwrap_err();
        assert_eq!(e, SessionError::AckTimeout(0));
    }

    #[test]
    fn the_peer_test_frame_is_confirmed_and_i_frames_before_start_refused() {
        let t = Instant::now();
        let mut s = Session::new(p(), t);
        let a = s.receive(Frame::U(UFunction::TestFrAct), t).unwrap();
        assert_eq!(a.send, vec![Frame::U(UFunction::TestFrCon)]);
        assert_eq!(s.receive(i(0, 0), t).unwrap_err(), SessionError::NotStarted);
    }

    #[test]
    fn sequence_numbers_wrap() {
        let t = Instant::now();
        let mut s = started(t);
        s.send_seq = 32767;
        s.recv_seq = 32767;
        s.send_i(vec![1], t);
        s.receive(i(32767, 0), t).unwrap();
        assert_eq!(s.recv_seq, 0);
        assert!(s.unacked.is_empty(), "N(R) 0 acknowledged 32767");
    }
}
