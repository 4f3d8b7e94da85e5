//! The register image of one simulated device and how a Modbus request acts
//! on it.
//!
//! Owns the four data tables, their sizes, which holding registers a master
//! may write, and the protocol checks every request passes (function,
//! quantity, address) before it touches a table. Must not touch the plant
//! models or sockets: the caller decides what a write means for the plant.
//! Anything here comes from the network, so nothing may panic.

use gridscada_config::RegisterKind;
use tokio_modbus::{ExceptionCode, Request, Response};

/// The most bits / registers the protocol allows in one request.
const MAX_READ_BITS: u16 = 2000;
const MAX_WRITE_BITS: u16 = 1968;
const MAX_READ_REGISTERS: u16 = 125;
const MAX_WRITE_REGISTERS: u16 = 123;
const MAX_RW_WRITE_REGISTERS: u16 = 121;

/// What the device accepts in one request (from its configuration, capped by
/// the protocol).
#[derive(Debug, Clone, Copy)]
pub(crate) struct Limits {
    pub max_read_registers: u16,
    pub max_read_bits: u16,
    pub max_write_registers: u16,
}

impl Default for Limits {
    fn default() -> Self {
        Limits {
            max_read_registers: MAX_READ_REGISTERS,
            max_read_bits: MAX_READ_BITS,
            max_write_registers: MAX_WRITE_REGISTERS,
        }
    }
}

/// A range a request wrote, with the values it replaced so that a write the
/// plant refuses can be undone.
#[derive(Debug, Clone)]
pub(crate) struct Written {
    pub kind: RegisterKind,
    pub start: u16,
    pub len: u16,
    old_bits: Vec<bool>,
    old_words: Vec<u16>,
}

#[derive(Debug, Clone, Default)]
pub(crate) struct RegisterImage {
    pub coils: Vec<bool>,
    pub discrete: Vec<bool>,
    pub input: Vec<u16>,
    pub holding: Vec<u16>,
    /// Per holding register: may a master write it?
    pub holding_writable: Vec<bool>,
    pub limits: Limits,
}

impl RegisterImage {
    pub fn new(sizes: [u16; 4], limits: Limits) -> Self {
        let [c, d, i, h] = sizes.map(usize::from);
        RegisterImage {
            coils: vec![false; c],
            discrete: vec![false; d],
            input: vec![0; i],
            holding: vec![0; h],
            holding_writable: vec![false; h],
            limits,
        }
    }

    /// Sets a bit (coil or discrete input) or a register bit; out of range is ignored.
    pub fn set_bit(&mut self, kind: RegisterKind, addr: u16, bit: Option<u8>, v: bool) {
        let a = usize::from(addr);
        match (kind, bit) {
            (RegisterKind::Coil, _) => {
                if let Some(x) = self.coils.get_mut(a) {
                    *x = v;
                }
            }
            (RegisterKind::DiscreteInput, _) => {
                if let Some(x) = self.discrete.get_mut(a) {
                    *x = v;
                }
            }
            (k, Some(b)) => {
                if let Some(w) = self.words_mut(k).get_mut(a) {
                    let mask = 1u16 << (b & 15);
                    *w = if v { *w | mask } else { *w & !mask };
                }
            }
            (k, None) => {
                if let Some(w) = self.words_mut(k).get_mut(a) {
                    *w = u16::from(v);
                }
            }
        }
    }

    pub fn bit(&self, kind: RegisterKind, addr: u16) -> Option<bool> {
        let a = usize::from(addr);
        match kind {
            RegisterKind::Coil => self.coils.get(a).copied(),
            RegisterKind::DiscreteInput => self.discrete.get(a).copied(),
            _ => None,
        }
    }

    pub fn set_words(&mut self, kind: RegisterKind, addr: u16, words: &[u16]) {
        let table = self.words_mut(kind);
        for (i, w) in words.iter().enumerate() {
            if let Some(x) = table.get_mut(usize::from(addr) + i) {
                *x = *w;
            }
        }
    }

    pub fn words(&self, kind: RegisterKind, addr: u16, len: u16) -> Option<&[u16]> {
        let table = match kind {
            RegisterKind::InputRegister => &self.input,
            RegisterKind::HoldingRegister => &self.holding,
            _ => return None,
        };
        table.get(usize::from(addr)..usize::from(addr) + usize::from(len))
    }

    fn words_mut(&mut self, kind: RegisterKind) -> &mut Vec<u16> {
        match kind {
            RegisterKind::HoldingRegister => &mut self.holding,
            _ => &mut self.input,
        }
    }

    /// Undoes a write the plant refused.
    pub fn restore(&mut self, w: &Written) {
        match w.kind {
            RegisterKind::Coil => {
                for (i, b) in w.old_bits.iter().enumerate() {
                    if let Some(x) = self.coils.get_mut(usize::from(w.start) + i) {
                        *x = *b;
                    }
                }
            }
            RegisterKind::HoldingRegister => {
                let old = w.old_words.clone();
                self.set_words(RegisterKind::HoldingRegister, w.start, &old);
            }
            _ => {}
        }
    }

    /// Carries out one request: checks, then reads or writes the tables.
    pub fn execute(
        &mut self,
        req: &Request<'_>,
    ) -> Result<(Response, Option<Written>), ExceptionCode> {
        let lim = self.limits;
        match req {
            Request::ReadCoils(a, q) => {
                check_quantity(*q, lim.max_read_bits.min(MAX_READ_BITS))?;
                let r = range(&self.coils, *a, *q)?;
                Ok((Response::ReadCoils(self.coils[r].to_vec()), None))
            }
            Request::ReadDiscreteInputs(a, q) => {
                check_quantity(*q, lim.max_read_bits.min(MAX_READ_BITS))?;
                let r = range(&self.discrete, *a, *q)?;
                Ok((
                    Response::ReadDiscreteInputs(self.discrete[r].to_vec()),
                    None,
                ))
            }
            Request::ReadInputRegisters(a, q) => {
                check_quantity(*q, lim.max_read_registers.min(MAX_READ_REGISTERS))?;
                let r = range(&self.input, *a, *q)?;
                Ok((Response::ReadInputRegisters(self.input[r].to_vec()), None))
            }
            Request::ReadHoldingRegisters(a, q) => {
                check_quantity(*q, lim.max_read_registers.min(MAX_READ_REGISTERS))?;
                let r = range(&self.holding, *a, *q)?;
                Ok((
                    Response::ReadHoldingRegisters(self.holding[r].to_vec()),
                    None,
                ))
            }
            Request::WriteSingleCoil(a, v) => {
                let w = self.write_coils(*a, &[*v])?;
                Ok((Response::WriteSingleCoil(*a, *v), Some(w)))
            }
            Request::WriteMultipleCoils(a, vs) => {
                let q = u16::try_from(vs.len()).map_err(|_| ExceptionCode::IllegalDataValue)?;
                check_quantity(q, MAX_WRITE_BITS)?;
                let w = self.write_coils(*a, vs)?;
                Ok((Response::WriteMultipleCoils(*a, q), Some(w)))
            }
            Request::WriteSingleRegister(a, v) => {
                let w = self.write_holding(*a, &[*v])?;
                Ok((Response::WriteSingleRegister(*a, *v), Some(w)))
            }
            Request::WriteMultipleRegisters(a, vs) => {
                let q = u16::try_from(vs.len()).map_err(|_| ExceptionCode::IllegalDataValue)?;
                check_quantity(q, lim.max_write_registers.min(MAX_WRITE_REGISTERS))?;
                let w = self.write_holding(*a, vs)?;
                Ok((Response::WriteMultipleRegisters(*a, q), Some(w)))
            }
            Request::MaskWriteRegister(a, and, or) => {
                let r = range(&self.holding, *a, 1)?;
                let cur = self.holding[r.start];
                let new = (cur & and) | (or & !and);
                let w = self.write_holding(*a, &[new])?;
                Ok((Response::MaskWriteRegister(*a, *and, *or), Some(w)))
            }
            Request::ReadWriteMultipleRegisters(ra, rq, wa, vs) => {
                check_quantity(*rq, lim.max_read_registers.min(MAX_READ_REGISTERS))?;
                let wq = u16::try_from(vs.len()).map_err(|_| ExceptionCode::IllegalDataValue)?;
                check_quantity(wq, lim.max_write_registers.min(MAX_RW_WRITE_REGISTERS))?;
                let r = range(&self.holding, *ra, *rq)?;
                // The write happens before the read (Modbus spec, function 0x17).
                let w = self.write_holding(*wa, vs)?;
                let out = self.holding[r].to_vec();
                Ok((Response::ReadWriteMultipleRegisters(out), Some(w)))
            }
            _ => Err(ExceptionCode::IllegalFunction),
        }
    }

    fn write_coils(&mut self, a: u16, vs: &[bool]) -> Result<Written, ExceptionCode> {
        let q = u16::try_from(vs.len()).map_err(|_| ExceptionCode::IllegalDataValue)?;
        let r = range(&self.coils, a, q)?;
        let old_bits = self.coils[r.clone()].to_vec();
        self.coils[r].copy_from_slice(vs);
        Ok(Written {
            kind: RegisterKind::Coil,
            start: a,
            len: q,
            old_bits,
            old_words: vec![],
        })
    }

    fn write_holding(&mut self, a: u16, vs: &[u16]) -> Result<Written, ExceptionCode> {
        let q = u16::try_from(vs.len()).map_err(|_| ExceptionCode::IllegalDataValue)?;
        let r = range(&self.holding, a, q)?;
        // Only registers that carry a writable tag take writes; the rest are
        // the controller's own (read-only) registers.
        if !self.holding_writable[r.clone()].iter().all(|w| *w) {
            return Err(ExceptionCode::IllegalDataAddress);
        }
        let old_words = self.holding[r.clone()].to_vec();
        self.holding[r].copy_from_slice(vs);
        Ok(Written {
            kind: RegisterKind::HoldingRegister,
            start: a,
            len: q,
            old_bits: vec![],
            old_words,
        })
    }
}

fn check_quantity(q: u16, max: u16) -> Result<(), ExceptionCode> {
    if q == 0 || q > max {
        Err(ExceptionCode::IllegalDataValue)
    } else {
        Ok(())
    }
}

fn range<T>(table: &[T], a: u16, q: u16) -> Result<std::ops::Range<usize>, ExceptionCode> {
    let start = usize::from(a);
    let end = start + usize::from(q);
    if q == 0 || end > table.len() {
        Err(ExceptionCode::IllegalDataAddress)
    } else {
        Ok(start..end)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::borrow::Cow;

    fn image() -> RegisterImage {
        let mut im = RegisterImage::new([8, 4, 22, 2], Limits::default());
        im.holding_writable = vec![true, true];
        im
    }

    #[test]
    fn out_of_range_reads_are_illegal_address() {
        let mut im = image();
        assert_eq!(
            im.execute(&Request::ReadCoils(7, 2)).unwrap_err(),
            ExceptionCode::IllegalDataAddress
        );
        assert_eq!(
            im.execute(&Request::ReadInputRegisters(u16::MAX, 125))
                .unwrap_err(),
            ExceptionCode::IllegalDataAddress
        );
        assert!(im.execute(&Request::ReadInputRegisters(0, 22)).is_ok());
    }

    #[test]
    fn bad_quantities_are_illegal_value() {
        let mut im = image();
        for req in [
            Request::ReadCoils(0, 0),
            Request::ReadDiscreteInputs(0, 2001),
            Request::ReadInputRegisters(0, 126),
            Request::ReadHoldingRegisters(0, 0),
            Request::WriteMultipleRegisters(0, Cow::Owned(vec![])),
        ] {
            assert_eq!(
                im.execute(&req).unwrap_err(),
                ExceptionCode::IllegalDataValue,
                "{req:?}"
            );
        }
    }

    #[test]
    fn unsupported_functions_are_illegal_function() {
        let mut im = image();
        assert_eq!(
            im.execute(&Request::ReportServerId).unwrap_err(),
            ExceptionCode::IllegalFunction
        );
        assert_eq!(
            im.execute(&Request::Custom(0x41, Cow::Owned(vec![1, 2])))
                .unwrap_err(),
            ExceptionCode::IllegalFunction
        );
    }

    #[test]
    fn read_only_holding_registers_refuse_writes() {
        let mut im = image();
        im.holding_writable[1] = false;
        assert_eq!(
            im.execute(&Request::WriteMultipleRegisters(0, Cow::Owned(vec![1, 2])))
                .unwrap_err(),
            ExceptionCode::IllegalDataAddress
        );
        assert_eq!(im.holding, vec![0, 0]);
        let (_, w) = im.execute(&Request::WriteSingleRegister(0, 7)).unwrap();
        assert_eq!(im.holding[0], 7);
        im.restore(&w.unwrap());
        assert_eq!(im.holding[0], 0);
    }

    #[test]
    fn mask_write_and_read_write() {
        let mut im = image();
        im.holding[0] = 0x00F0;
        im.execute(&Request::MaskWriteRegister(0, 0x00FF, 0x0F00))
            .unwrap();
        // (current AND and) OR (or AND NOT and)
        assert_eq!(im.holding[0], 0x0FF0);
        let (r, _) = im
            .execute(&Request::ReadWriteMultipleRegisters(
                0,
                2,
                1,
                Cow::Owned(vec![9]),
            ))
            .unwrap();
        assert_eq!(r, Response::ReadWriteMultipleRegisters(vec![0x0FF0, 9]));
    }
}
