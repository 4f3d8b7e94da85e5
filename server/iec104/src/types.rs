//! Type identifications and causes of transmission (IEC 60870-5-101 7.2.1 and
//! 7.2.3), named as in the standard.

use std::fmt;

macro_rules! type_ids {
    ($($name:ident = $n:literal, $desc:literal;)*) => {
        /// The type identifications this codec knows: the ones IEC 104 allows
        /// that a SCADA uses (no protection-equipment events, no file transfer,
        /// no parameter loading).
        #[allow(non_camel_case_types)]
        #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
        #[repr(u8)]
        pub enum TypeId {
            $(#[doc = $desc] $name = $n,)*
        }

        impl TypeId {
            /// Every type identification, in numeric order.
            pub const ALL: &'static [TypeId] = &[$(TypeId::$name,)*];

            /// The type with this number, or `None` for one this codec does not know.
            pub fn from_u8(n: u8) -> Option<TypeId> {
                match n {
                    $($n => Some(TypeId::$name),)*
                    _ => None,
                }
            }

            /// The standard's mnemonic, e.g. "M_ME_NC_1".
            pub fn name(self) -> &'static str {
                match self {
                    $(TypeId::$name => stringify!($name),)*
                }
            }

            /// The standard's description, e.g. "measured value, short floating point number".
            pub fn description(self) -> &'static str {
                match self {
                    $(TypeId::$name => $desc,)*
                }
            }
        }
    };
}

type_ids! {
    M_SP_NA_1 = 1, "single-point information";
    M_DP_NA_1 = 3, "double-point information";
    M_ST_NA_1 = 5, "step position information";
    M_BO_NA_1 = 7, "bitstring of 32 bit";
    M_ME_NA_1 = 9, "measured value, normalized value";
    M_ME_NB_1 = 11, "measured value, scaled value";
    M_ME_NC_1 = 13, "measured value, short floating point number";
    M_IT_NA_1 = 15, "integrated totals";
    M_ME_ND_1 = 21, "measured value, normalized value without quality descriptor";
    M_SP_TB_1 = 30, "single-point information with time tag CP56Time2a";
    M_DP_TB_1 = 31, "double-point information with time tag CP56Time2a";
    M_ST_TB_1 = 32, "step position information with time tag CP56Time2a";
    M_BO_TB_1 = 33, "bitstring of 32 bit with time tag CP56Time2a";
    M_ME_TD_1 = 34, "measured value, normalized value with time tag CP56Time2a";
    M_ME_TE_1 = 35, "measured value, scaled value with time tag CP56Time2a";
    M_ME_TF_1 = 36, "measured value, short floating point number with time tag CP56Time2a";
    M_IT_TB_1 = 37, "integrated totals with time tag CP56Time2a";
    C_SC_NA_1 = 45, "single command";
    C_DC_NA_1 = 46, "double command";
    C_RC_NA_1 = 47, "regulating step command";
    C_SE_NA_1 = 48, "set point command, normalized value";
    C_SE_NB_1 = 49, "set point command, scaled value";
    C_SE_NC_1 = 50, "set point command, short floating point number";
    C_BO_NA_1 = 51, "bitstring of 32 bit command";
    C_SC_TA_1 = 58, "single command with time tag CP56Time2a";
    C_DC_TA_1 = 59, "double command with time tag CP56Time2a";
    C_RC_TA_1 = 60, "regulating step command with time tag CP56Time2a";
    C_SE_TA_1 = 61, "set point command, normalized value with time tag CP56Time2a";
    C_SE_TB_1 = 62, "set point command, scaled value with time tag CP56Time2a";
    C_SE_TC_1 = 63, "set point command, short floating point number with time tag CP56Time2a";
    C_BO_TA_1 = 64, "bitstring of 32 bit command with time tag CP56Time2a";
    M_EI_NA_1 = 70, "end of initialization";
    C_IC_NA_1 = 100, "interrogation command";
    C_CI_NA_1 = 101, "counter interrogation command";
    C_RD_NA_1 = 102, "read command";
    C_CS_NA_1 = 103, "clock synchronization command";
    C_TS_TA_1 = 107, "test command with time tag CP56Time2a";
}

impl TypeId {
    /// The number on the wire.
    pub fn as_u8(self) -> u8 {
        self as u8
    }

    /// Whether each object carries a CP56Time2a after its element. C_CS_NA_1
    /// is not counted: its time *is* the element.
    pub fn carries_time(self) -> bool {
        matches!(self.as_u8(), 30..=37 | 58..=64 | 107)
    }

    /// Whether the type travels in control direction (a process or system
    /// command, `C_` in its name), so that a station must confirm it.
    pub fn is_command(self) -> bool {
        self.name().starts_with("C_")
    }

    /// Whether an ASDU of this type may use SQ=1 (one IOA, then consecutive
    /// elements): the monitoring types (`M_`, end of initialisation aside).
    /// The standard's type definitions give SQ=1 to those without time tag,
    /// but lib60870 answers a general interrogation with time-tagged types
    /// in SQ=1 form, so a controlling station must take them; commands are
    /// one object each.
    pub fn allows_sequence(self) -> bool {
        self.name().starts_with("M_") && self != TypeId::M_EI_NA_1
    }

    /// Octets of one information element, time tag included, IOA excluded.
    pub fn element_len(self) -> usize {
        use TypeId::*;
        let element = match self {
            M_SP_NA_1 | M_DP_NA_1 | M_SP_TB_1 | M_DP_TB_1 => 1,
            M_ST_NA_1 | M_ST_TB_1 => 2,
            M_BO_NA_1 | M_BO_TB_1 => 5,
            M_ME_NA_1 | M_ME_NB_1 | M_ME_TD_1 | M_ME_TE_1 => 3,
            M_ME_NC_1 | M_ME_TF_1 => 5,
            M_IT_NA_1 | M_IT_TB_1 => 5,
            M_ME_ND_1 => 2,
            M_EI_NA_1 => 1,
            C_SC_NA_1 | C_DC_NA_1 | C_RC_NA_1 | C_SC_TA_1 | C_DC_TA_1 | C_RC_TA_1 => 1,
            C_SE_NA_1 | C_SE_NB_1 | C_SE_TA_1 | C_SE_TB_1 => 3,
            C_SE_NC_1 | C_SE_TC_1 => 5,
            C_BO_NA_1 | C_BO_TA_1 => 4,
            C_IC_NA_1 | C_CI_NA_1 => 1,
            C_RD_NA_1 => 0,
            C_CS_NA_1 => crate::time::CP56_LEN,
            C_TS_TA_1 => 2,
        };
        element
            + if self.carries_time() {
                crate::time::CP56_LEN
            } else {
                0
            }
    }
}

impl fmt::Display for TypeId {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// Cause of transmission (6 bits). Named after the standard's abbreviations
/// (spont, actcon, inro1 ...); numbers the standard leaves unused or private
/// are kept as `Other`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Cause {
    /// per/cyc (1): periodic, cyclic.
    PerCyc,
    /// back (2): background scan.
    Back,
    /// spont (3): spontaneous.
    Spont,
    /// init (4): initialized.
    Init,
    /// req (5): request or requested.
    Req,
    /// act (6): activation.
    Act,
    /// actcon (7): activation confirmation.
    ActCon,
    /// deact (8): deactivation.
    Deact,
    /// deactcon (9): deactivation confirmation.
    DeactCon,
    /// actterm (10): activation termination.
    ActTerm,
    /// retrem (11): return information caused by a remote command.
    RetRem,
    /// retloc (12): return information caused by a local command.
    RetLoc,
    /// file (13): file transfer.
    File,
    /// inrogen (20): interrogated by station interrogation.
    InroGen,
    /// inro1..inro16 (21..=36): interrogated by group interrogation; holds
    /// the group, 1..=16.
    Inro(u8),
    /// reqcogen (37): requested by general counter request.
    ReqCoGen,
    /// reqco1..reqco4 (38..=41): requested by group counter request; holds
    /// the group, 1..=4.
    ReqCo(u8),
    /// 44: unknown type identification.
    UnknownType,
    /// 45: unknown cause of transmission.
    UnknownCause,
    /// 46: unknown common address of ASDU.
    UnknownCommonAddress,
    /// 47: unknown information object address.
    UnknownIoa,
    /// Any other number, 0..=63.
    Other(u8),
}

impl Cause {
    /// The cause for the six low bits of `n`.
    pub fn from_u8(n: u8) -> Cause {
        match n & 0x3F {
            1 => Cause::PerCyc,
            2 => Cause::Back,
            3 => Cause::Spont,
            4 => Cause::Init,
            5 => Cause::Req,
            6 => Cause::Act,
            7 => Cause::ActCon,
            8 => Cause::Deact,
            9 => Cause::DeactCon,
            10 => Cause::ActTerm,
            11 => Cause::RetRem,
            12 => Cause::RetLoc,
            13 => Cause::File,
            20 => Cause::InroGen,
            n @ 21..=36 => Cause::Inro(n - 20),
            37 => Cause::ReqCoGen,
            n @ 38..=41 => Cause::ReqCo(n - 37),
            44 => Cause::UnknownType,
            45 => Cause::UnknownCause,
            46 => Cause::UnknownCommonAddress,
            47 => Cause::UnknownIoa,
            n => Cause::Other(n),
        }
    }

    /// The number on the wire, or `None` for a hand-built value that has none
    /// (a group outside its range, `Other` past 63 or naming a known cause).
    pub fn to_u8(self) -> Option<u8> {
        let n = match self {
            Cause::PerCyc => 1,
            Cause::Back => 2,
            Cause::Spont => 3,
            Cause::Init => 4,
            Cause::Req => 5,
            Cause::Act => 6,
            Cause::ActCon => 7,
            Cause::Deact => 8,
            Cause::DeactCon => 9,
            Cause::ActTerm => 10,
            Cause::RetRem => 11,
            Cause::RetLoc => 12,
            Cause::File => 13,
            Cause::InroGen => 20,
            Cause::Inro(g @ 1..=16) => 20 + g,
            Cause::Inro(_) => return None,
            Cause::ReqCoGen => 37,
            Cause::ReqCo(g @ 1..=4) => 37 + g,
            Cause::ReqCo(_) => return None,
            Cause::UnknownType => 44,
            Cause::UnknownCause => 45,
            Cause::UnknownCommonAddress => 46,
            Cause::UnknownIoa => 47,
            Cause::Other(n) if n <= 63 && Cause::from_u8(n) == Cause::Other(n) => n,
            Cause::Other(_) => return None,
        };
        Some(n)
    }

    /// The standard's abbreviation, e.g. "spont" ("inro" and "reqco" without
    /// their group, "other" for unnamed numbers).
    pub fn name(self) -> &'static str {
        match self {
            Cause::PerCyc => "per/cyc",
            Cause::Back => "back",
            Cause::Spont => "spont",
            Cause::Init => "init",
            Cause::Req => "req",
            Cause::Act => "act",
            Cause::ActCon => "actcon",
            Cause::Deact => "deact",
            Cause::DeactCon => "deactcon",
            Cause::ActTerm => "actterm",
            Cause::RetRem => "retrem",
            Cause::RetLoc => "retloc",
            Cause::File => "file",
            Cause::InroGen => "inrogen",
            Cause::Inro(_) => "inro",
            Cause::ReqCoGen => "reqcogen",
            Cause::ReqCo(_) => "reqco",
            Cause::UnknownType => "unknown type identification",
            Cause::UnknownCause => "unknown cause of transmission",
            Cause::UnknownCommonAddress => "unknown common address of ASDU",
            Cause::UnknownIoa => "unknown information object address",
            Cause::Other(_) => "other",
        }
    }
}

impl fmt::Display for Cause {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Cause::Inro(g) | Cause::ReqCo(g) => write!(f, "{}{g}", self.name()),
            Cause::Other(n) => write!(f, "cause {n}"),
            _ => f.write_str(self.name()),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn type_numbers_and_names() {
        for &t in TypeId::ALL {
            assert_eq!(TypeId::from_u8(t.as_u8()), Some(t));
        }
        assert_eq!(TypeId::ALL.len(), 37);
        assert_eq!(TypeId::M_SP_NA_1.as_u8(), 1);
        assert_eq!(TypeId::C_TS_TA_1.as_u8(), 107);
        assert_eq!(TypeId::M_ME_NC_1.name(), "M_ME_NC_1");
        assert_eq!(TypeId::from_u8(2), None);
        assert_eq!(TypeId::from_u8(0), None);
        assert!(TypeId::M_SP_TB_1.carries_time());
        assert!(TypeId::C_SE_TC_1.carries_time());
        assert!(!TypeId::C_CS_NA_1.carries_time());
        assert!(!TypeId::M_ME_NC_1.carries_time());
        assert!(TypeId::C_IC_NA_1.is_command());
        assert!(TypeId::C_SC_NA_1.is_command());
        assert!(!TypeId::M_EI_NA_1.is_command());
        assert_eq!(TypeId::M_ME_TF_1.element_len(), 12);
        assert_eq!(TypeId::C_TS_TA_1.element_len(), 9);
        assert_eq!(TypeId::C_RD_NA_1.element_len(), 0);
    }

    #[test]
    fn causes_round_trip_through_all_64_numbers() {
        for n in 0..64u8 {
            let c = Cause::from_u8(n);
            assert_eq!(c.to_u8(), Some(n), "{c:?}");
        }
        assert_eq!(Cause::from_u8(21), Cause::Inro(1));
        assert_eq!(Cause::from_u8(36), Cause::Inro(16));
        assert_eq!(Cause::from_u8(41), Cause::ReqCo(4));
        assert_eq!(Cause::from_u8(44), Cause::UnknownType);
        assert_eq!(Cause::from_u8(14), Cause::Other(14));
        assert_eq!(Cause::Inro(17).to_u8(), None);
        assert_eq!(Cause::Other(3).to_u8(), None);
        assert_eq!(Cause::Other(64).to_u8(), None);
        assert_eq!(Cause::Inro(5).to_string(), "inro5");
        assert_eq!(Cause::ActCon.to_string(), "actcon");
    }
}
