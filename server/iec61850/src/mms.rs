//! MMS (ISO 9506) PDUs an IEC 61850 client sends and receives: initiate,
//! read, write, get-name-list, get-variable-access-attributes,
//! information reports, conclude, reject and service errors.
//!
//! Requests are built from plain values; received PDUs decode into
//! [`Pdu`], never panicking, with every error located by octet offset.

use crate::ber::{BerError, BitString, Reader, Tag, Tlv, Writer, MAX_DEPTH};
use crate::data::Data;

/// An MMS object name.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub enum ObjectName {
    /// Named in the whole server (e.g. `RPT`, `LastApplError`).
    Vmd(String),
    /// Named in a domain: for IEC 61850 the domain is the logical device
    /// (`TESTLD0`) and the item the `$`-path (`GGIO1$ST$Ind1$stVal`).
    Domain(String, String),
}

impl ObjectName {
    fn encode(&self, w: &mut Writer) {
        match self {
            ObjectName::Vmd(id) => w.primitive(Tag::ctx(0), id.as_bytes()),
            ObjectName::Domain(d, i) => w.constructed(Tag::ctx_c(1), |w| {
                w.primitive(Tag::VISIBLE_STRING, d.as_bytes());
                w.primitive(Tag::VISIBLE_STRING, i.as_bytes());
            }),
        }
    }

    fn decode(t: &Tlv<'_>) -> Result<ObjectName, BerError> {
        match (t.tag.number, t.tag.constructed) {
            (0, false) => Ok(ObjectName::Vmd(t.as_str()?.to_string())),
            (1, true) => {
                let mut r = t.children();
                let d = r
                    .expect(Tag::VISIBLE_STRING, "domain id")?
                    .as_str()?
                    .to_string();
                let i = r
                    .expect(Tag::VISIBLE_STRING, "item id")?
                    .as_str()?
                    .to_string();
                Ok(ObjectName::Domain(d, i))
            }
            (2, false) => Ok(ObjectName::Vmd(t.as_str()?.to_string())),
            _ => Err(t.error(format!("object name with tag {}", t.tag))),
        }
    }

    /// The item (or VMD-specific) identifier.
    pub fn item(&self) -> &str {
        match self {
            ObjectName::Vmd(i) | ObjectName::Domain(_, i) => i,
        }
    }
}

impl std::fmt::Display for ObjectName {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            ObjectName::Vmd(i) => f.write_str(i),
            ObjectName::Domain(d, i) => write!(f, "{d}/{i}"),
        }
    }
}

/// What an IED's MMS server accepts after the initiate exchange.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Negotiated {
    /// Largest MMS PDU either side may send.
    pub max_pdu: u32,
    /// Requests we may have outstanding at once.
    pub max_outstanding: u32,
    pub nesting_level: u32,
}

/// Largest MMS PDU we propose (and then accept, per the response).
pub const PROPOSED_MAX_PDU: u32 = 65_000;

/// The initiate-RequestPDU: our limits, version 1, and the parameter and
/// service support bits of an IEC 61850 client.
pub fn initiate_request() -> Vec<u8> {
    let mut w = Writer::new();
    w.constructed(Tag::ctx_c(8), |w| {
        w.integer(Tag::ctx(0), i64::from(PROPOSED_MAX_PDU));
        w.integer(Tag::ctx(1), 5);
        w.integer(Tag::ctx(2), 5);
        w.integer(Tag::ctx(3), 10);
        w.constructed(Tag::ctx_c(4), |w| {
            w.integer(Tag::ctx(0), 1);
            // str1, str2, vnam, valt, vlis (the CBBs IEC 61850-8-1 requires).
            w.primitive(Tag::ctx(1), &[0x05, 0xf1, 0x00]);
            // Services we call: status, getNameList, identify, read, write,
            // getVariableAccessAttributes, getNamedVariableListAttributes,
            // file services, informationReport, conclude and so on.
            w.primitive(
                Tag::ctx(2),
                &[
                    0x03, 0xee, 0x1c, 0x00, 0x00, 0x04, 0x08, 0x00, 0x00, 0x79, 0xef, 0x18,
                ],
            );
        });
    });
    w.into_vec()
}

/// A confirmed service request's body.
#[derive(Debug, Clone, PartialEq)]
pub enum Request {
    /// Read variables by name.
    Read(Vec<ObjectName>),
    /// Read a named variable list (an IEC 61850 dataset).
    ReadList(ObjectName),
    /// Write one variable.
    Write(ObjectName, Data),
    /// Names of objects of `class` (0 named variable, 2 named variable
    /// list, 9 domain) in `domain` (or the VMD), after `continue_after`.
    GetNameList {
        class: u8,
        domain: Option<String>,
        continue_after: Option<String>,
    },
    /// A variable's type description.
    GetVariableAccessAttributes(ObjectName),
    /// A named variable list's members (a dataset's FCDAs).
    GetNamedVariableListAttributes(ObjectName),
}

impl Request {
    /// The confirmed-RequestPDU with invoke id `invoke`.
    pub fn encode(&self, invoke: u32) -> Vec<u8> {
        let mut w = Writer::new();
        w.constructed(Tag::ctx_c(0), |w| {
            w.unsigned(Tag::INTEGER, u64::from(invoke));
            match self {
                Request::Read(names) => w.constructed(Tag::ctx_c(4), |w| {
                    w.constructed(Tag::ctx_c(1), |w| list_of_variables(w, names));
                }),
                Request::ReadList(name) => w.constructed(Tag::ctx_c(4), |w| {
                    w.constructed(Tag::ctx_c(1), |w| {
                        w.constructed(Tag::ctx_c(1), |w| name.encode(w))
                    });
                }),
                Request::Write(name, data) => w.constructed(Tag::ctx_c(5), |w| {
                    list_of_variables(w, std::slice::from_ref(name));
                    w.constructed(Tag::ctx_c(0), |w| data.encode(w));
                }),
                Request::GetNameList {
                    class,
                    domain,
                    continue_after,
                } => w.constructed(Tag::ctx_c(1), |w| {
                    w.constructed(Tag::ctx_c(0), |w| w.integer(Tag::ctx(0), i64::from(*class)));
                    w.constructed(Tag::ctx_c(1), |w| match domain {
                        Some(d) => w.primitive(Tag::ctx(1), d.as_bytes()),
                        None => w.primitive(Tag::ctx(0), &[]),
                    });
                    if let Some(after) = continue_after {
                        w.primitive(Tag::ctx(2), after.as_bytes());
                    }
                }),
                Request::GetVariableAccessAttributes(name) => w.constructed(Tag::ctx_c(6), |w| {
                    w.constructed(Tag::ctx_c(0), |w| name.encode(w))
                }),
                Request::GetNamedVariableListAttributes(name) => {
                    w.constructed(Tag::ctx_c(12), |w| name.encode(w))
                }
            }
        });
        w.into_vec()
    }
}

fn list_of_variables(w: &mut Writer, names: &[ObjectName]) {
    w.constructed(Tag::ctx_c(0), |w| {
        for n in names {
            w.constructed(Tag::SEQUENCE, |w| {
                w.constructed(Tag::ctx_c(0), |w| n.encode(w))
            });
        }
    });
}

/// The conclude-RequestPDU (an orderly end of the association).
pub fn conclude_request() -> Vec<u8> {
    vec![0x8b, 0x00]
}

/// One result of a read or a report: the value, or why there is none.
pub type AccessResult = Result<Data, DataAccessError>;

/// MMS `DataAccessError`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct DataAccessError(pub i64);

impl std::fmt::Display for DataAccessError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        const NAMES: [&str; 12] = [
            "object invalidated",
            "hardware fault",
            "temporarily unavailable",
            "object access denied",
            "object undefined",
            "invalid address",
            "type unsupported",
            "type inconsistent",
            "object attribute inconsistent",
            "object access unsupported",
            "object non-existent",
            "object value invalid",
        ];
        match usize::try_from(self.0).ok().and_then(|i| NAMES.get(i)) {
            Some(n) => write!(f, "{n} ({})", self.0),
            None => write!(f, "data access error {}", self.0),
        }
    }
}

/// A variable's type, from get-variable-access-attributes.
#[derive(Debug, Clone, PartialEq)]
pub enum TypeSpec {
    Array {
        count: u32,
        element: Box<TypeSpec>,
    },
    Structure(Vec<(String, TypeSpec)>),
    Boolean,
    BitString(i64),
    Integer(u8),
    Unsigned(u8),
    Float,
    OctetString(i64),
    VisibleString(i64),
    MmsString(i64),
    UtcTime,
    BinaryTime,
    /// Named type or one this client does not interpret.
    Other(u32),
}

impl TypeSpec {
    fn decode(t: &Tlv<'_>, depth: usize) -> Result<TypeSpec, BerError> {
        if depth >= MAX_DEPTH {
            return Err(t.error(format!("type nested deeper than {MAX_DEPTH}")));
        }
        let small = |t: &Tlv<'_>| t.as_i64().unwrap_or(0);
        Ok(match t.tag.number {
            1 => {
                let mut r = t.children();
                r.optional(Tag::ctx(0))?;
                let count = r.expect(Tag::ctx(1), "numberOfElements")?.as_u32()?;
                let el = r.expect(Tag::ctx_c(2), "elementType")?;
                let inner = el.children().read("element type")?;
                TypeSpec::Array {
                    count,
                    element: Box::new(TypeSpec::decode(&inner, depth + 1)?),
                }
            }
            2 => {
                let mut r = t.children();
                r.optional(Tag::ctx(0))?;
                let comps = r.expect(Tag::ctx_c(1), "components")?;
                let mut out = Vec::new();
                for c in comps.children() {
                    let mut cr = c?.children();
                    let name = match cr.optional(Tag::ctx(0))? {
                        Some(n) => n.as_str()?.to_string(),
                        None => String::new(),
                    };
                    let ty = cr.expect(Tag::ctx_c(1), "componentType")?;
                    let inner = ty.children().read("component type")?;
                    out.push((name, TypeSpec::decode(&inner, depth + 1)?));
                }
                TypeSpec::Structure(out)
            }
            3 => TypeSpec::Boolean,
            4 => TypeSpec::BitString(small(t)),
            5 => TypeSpec::Integer(small(t) as u8),
            6 => TypeSpec::Unsigned(small(t) as u8),
            7 => TypeSpec::Float,
            9 => TypeSpec::OctetString(small(t)),
            10 => TypeSpec::VisibleString(small(t)),
            16 => TypeSpec::MmsString(small(t)),
            17 => TypeSpec::UtcTime,
            12 => TypeSpec::BinaryTime,
            n => TypeSpec::Other(n),
        })
    }

    /// The `$`-paths of the leaves under this type, in the order MMS sends
    /// their values (structure components in order, depth first).
    pub fn leaves(&self, prefix: &str, out: &mut Vec<String>) {
        match self {
            TypeSpec::Structure(comps) => {
                for (name, ty) in comps {
                    let path = if prefix.is_empty() {
                        name.clone()
                    } else {
                        format!("{prefix}${name}")
                    };
                    ty.leaves(&path, out);
                }
            }
            _ => out.push(prefix.to_string()),
        }
    }
}

/// A confirmed service response's body.
#[derive(Debug, Clone, PartialEq)]
pub enum Response {
    Read(Vec<AccessResult>),
    /// One result per written variable.
    Write(Vec<Result<(), DataAccessError>>),
    GetNameList {
        names: Vec<String>,
        more_follows: bool,
    },
    GetVariableAccessAttributes(TypeSpec),
    GetNamedVariableListAttributes(Vec<ObjectName>),
    /// A service this client does not decode: its tag number.
    Other(u32),
}

/// MMS `ServiceError`: its class and code.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ServiceError {
    pub class: u32,
    pub code: i64,
}

impl std::fmt::Display for ServiceError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let class = [
            "vmd-state",
            "application-reference",
            "definition",
            "resource",
            "service",
            "service-preempt",
            "time-resolution",
            "access",
            "initiate",
            "conclude",
            "cancel",
            "file",
            "others",
        ]
        .get(self.class as usize)
        .copied()
        .unwrap_or("unknown");
        let code = match (self.class, self.code) {
            (2, 1) => " object undefined",
            (2, 3) => " type unsupported",
            (2, 4) => " type inconsistent",
            (7, 1) => " object access unsupported",
            (7, 2) => " object non-existent",
            (7, 3) => " object access denied",
            (7, 4) => " object invalidated",
            (3, 1) => " memory unavailable",
            (0, 1) => " vmd-state conflict",
            _ => "",
        };
        write!(
            f,
            "service error: {class}{code} (class {}, code {})",
            self.class, self.code
        )
    }
}

/// A received MMS PDU.
#[derive(Debug, Clone, PartialEq)]
pub enum Pdu {
    Response {
        invoke: u32,
        response: Response,
    },
    Error {
        invoke: u32,
        error: ServiceError,
    },
    /// The peer rejected a PDU of ours (e.g. one it could not decode).
    Reject {
        invoke: Option<u32>,
        reason: String,
    },
    /// An unconfirmed information report: a report (`RPT`), a command
    /// termination, or a `LastApplError`.
    InformationReport(InformationReport),
    InitiateResponse(Negotiated),
    InitiateError(ServiceError),
    /// The peer asks to end the association.
    ConcludeRequest,
    ConcludeResponse,
    /// A PDU a client never receives (e.g. a request): its tag.
    Unexpected(String),
}

/// An information report: what it names and its access results.
#[derive(Debug, Clone, PartialEq)]
pub struct InformationReport {
    /// The named variable list (`RPT`) or the variables listed.
    pub names: ReportNames,
    pub results: Vec<AccessResult>,
}

#[derive(Debug, Clone, PartialEq)]
pub enum ReportNames {
    List(ObjectName),
    Variables(Vec<ObjectName>),
}

impl Pdu {
    /// Decodes one MMS PDU.
    pub fn decode(b: &[u8]) -> Result<Pdu, BerError> {
        let t = Reader::new(b).read("MMS PDU")?;
        match (t.tag.number, t.tag.constructed) {
            (1, true) => {
                let mut r = t.children();
                let invoke = r.expect(Tag::INTEGER, "invokeID")?.as_u32()?;
                let service = r.read("confirmed service response")?;
                Ok(Pdu::Response {
                    invoke,
                    response: decode_response(&service)?,
                })
            }
            (2, true) => {
                let mut r = t.children();
                let invoke = r.expect(Tag::ctx(0), "invokeID")?.as_u32()?;
                r.optional(Tag::ctx(1))?; // modifierPosition
                let se = r.expect(Tag::ctx_c(2), "serviceError")?;
                Ok(Pdu::Error {
                    invoke,
                    error: service_error(&se)?,
                })
            }
            (4, true) => {
                let mut r = t.children();
                let invoke = r.optional(Tag::ctx(0))?.map(|t| t.as_u32()).transpose()?;
                let reason = match r.read("rejectReason") {
                    Ok(t) => format!(
                        "reject reason [{}] {}",
                        t.tag.number,
                        t.as_i64().unwrap_or(-1)
                    ),
                    Err(_) => "no reason given".to_string(),
                };
                Ok(Pdu::Reject { invoke, reason })
            }
            (3, true) => {
                let inner = t.children().expect(Tag::ctx_c(0), "informationReport")?;
                Ok(Pdu::InformationReport(decode_information_report(&inner)?))
            }
            (9, true) => Ok(Pdu::InitiateResponse(decode_initiate_response(&t)?)),
            (10, true) => Ok(Pdu::InitiateError(service_error(&t)?)),
            (11, false) => Ok(Pdu::ConcludeRequest),
            (12, false) => Ok(Pdu::ConcludeResponse),
            (n, _) => Ok(Pdu::Unexpected(format!("MMS PDU [{n}]"))),
        }
    }
}

fn decode_initiate_response(t: &Tlv<'_>) -> Result<Negotiated, BerError> {
    let mut n = Negotiated {
        max_pdu: PROPOSED_MAX_PDU,
        max_outstanding: 1,
        nesting_level: 10,
    };
    for c in t.children() {
        let c = c?;
        match c.tag {
            tag if tag == Tag::ctx(0) => n.max_pdu = c.as_u32()?,
            tag if tag == Tag::ctx(2) => n.max_outstanding = c.as_u32()?.max(1),
            tag if tag == Tag::ctx(3) => n.nesting_level = c.as_u32()?,
            _ => {}
        }
    }
    Ok(n)
}

fn service_error(t: &Tlv<'_>) -> Result<ServiceError, BerError> {
    let class = t.children().expect(Tag::ctx_c(0), "errorClass")?;
    let inner = class.children().read("error class choice")?;
    Ok(ServiceError {
        class: inner.tag.number,
        code: inner.as_i64()?,
    })
}

fn access_results(t: &Tlv<'_>) -> Result<Vec<AccessResult>, BerError> {
    t.children()
        .map(|c| {
            let c = c?;
            if c.tag == Tag::ctx(0) {
                Ok(Err(DataAccessError(c.as_i64()?)))
            } else {
                Data::decode(&c).map(Ok)
            }
        })
        .collect()
}

fn decode_response(t: &Tlv<'_>) -> Result<Response, BerError> {
    Ok(match (t.tag.number, t.tag.constructed) {
        (4, true) => {
            let mut r = t.children();
            r.optional(Tag::ctx_c(0))?; // variableAccessSpecification
            let list = r.expect(Tag::ctx_c(1), "listOfAccessResult")?;
            Response::Read(access_results(&list)?)
        }
        (5, true) => Response::Write(
            t.children()
                .map(|c| {
                    let c = c?;
                    Ok(match c.tag.number {
                        0 => Err(DataAccessError(c.as_i64()?)),
                        _ => Ok(()),
                    })
                })
                .collect::<Result<_, BerError>>()?,
        ),
        (1, true) => {
            let mut r = t.children();
            let list = r.expect(Tag::ctx_c(0), "listOfIdentifier")?;
            let names = list
                .children()
                .map(|c| c.and_then(|c| c.as_str().map(str::to_string)))
                .collect::<Result<_, _>>()?;
            let more_follows = match r.optional(Tag::ctx(1))? {
                Some(m) => m.as_bool()?,
                None => true,
            };
            Response::GetNameList {
                names,
                more_follows,
            }
        }
        (6, true) => {
            let mut r = t.children();
            r.optional(Tag::ctx(0))?; // mmsDeletable
            r.optional(Tag::ctx_c(1))?; // address
            let ts = r.expect(Tag::ctx_c(2), "typeSpecification")?;
            let inner = ts.children().read("type description")?;
            Response::GetVariableAccessAttributes(TypeSpec::decode(&inner, 0)?)
        }
        (12, true) => {
            let mut r = t.children();
            r.optional(Tag::ctx(0))?; // mmsDeletable
            let list = r.expect(Tag::ctx_c(1), "listOfVariable")?;
            let mut names = Vec::new();
            for v in list.children() {
                let spec = v?
                    .children()
                    .expect(Tag::ctx_c(0), "variableSpecification name")?;
                names.push(ObjectName::decode(&spec.children().read("object name")?)?);
            }
            Response::GetNamedVariableListAttributes(names)
        }
        (n, _) => Response::Other(n),
    })
}

fn decode_information_report(t: &Tlv<'_>) -> Result<InformationReport, BerError> {
    let mut r = t.children();
    let spec = r.read("variableAccessSpecification")?;
    let names = match (spec.tag.number, spec.tag.constructed) {
        (1, true) => ReportNames::List(ObjectName::decode(
            &spec.children().read("variable list name")?,
        )?),
        (0, true) => {
            let mut names = Vec::new();
            for v in spec.children() {
                let name = v?
                    .children()
                    .expect(Tag::ctx_c(0), "variableSpecification name")?;
                names.push(ObjectName::decode(&name.children().read("object name")?)?);
            }
            ReportNames::Variables(names)
        }
        _ => return Err(spec.error(format!("variable access specification {}", spec.tag))),
    };
    let list = r.expect(Tag::ctx_c(0), "listOfAccessResult")?;
    Ok(InformationReport {
        names,
        results: access_results(&list)?,
    })
}

/// A bit string of `n` bits with the given bits set (e.g. trigger options).
pub fn bits(n: usize, set: &[usize]) -> BitString {
    let v: Vec<bool> = (0..n).map(|i| set.contains(&i)).collect();
    BitString::from_bits(&v)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_read_request_names_domain_and_item() {
        let r = Request::Read(vec![ObjectName::Domain(
            "TESTLD0".into(),
            "GGIO1$ST$Ind1$stVal".into(),
        )])
        .encode(7);
        // confirmed-RequestPDU, invoke 7, read [4] { [1] { [0] { SEQ { [0] { [1] { "TESTLD0" "GGIO1$ST$Ind1$stVal" } } } } } }
        assert_eq!(&r[..6], &[0xa0, r[1], 0x02, 0x01, 0x07, 0xa4]);
        let text = String::from_utf8_lossy(&r);
        assert!(text.contains("TESTLD0") && text.contains("GGIO1$ST$Ind1$stVal"));
    }

    #[test]
    fn a_read_response_with_a_failure_and_a_structure() {
        let mut w = Writer::new();
        w.constructed(Tag::ctx_c(1), |w| {
            w.integer(Tag::INTEGER, 300);
            w.constructed(Tag::ctx_c(4), |w| {
                w.constructed(Tag::ctx_c(1), |w| {
                    w.integer(Tag::ctx(0), 10);
                    Data::Structure(vec![Data::Float(1.0), Data::Boolean(true)]).encode(w);
                })
            })
        });
        let pdu = Pdu::decode(&w.buf).unwrap();
        assert_eq!(
            pdu,
            Pdu::Response {
                invoke: 300,
                response: Response::Read(vec![
                    Err(DataAccessError(10)),
                    Ok(Data::Structure(vec![Data::Float(1.0), Data::Boolean(true)]))
                ])
            }
        );
        assert_eq!(DataAccessError(10).to_string(), "object non-existent (10)");
    }

    #[test]
    fn truncated_pdus_are_errors_not_panics() {
        let r = Request::Write(
            ObjectName::Domain("A".into(), "B".into()),
            Data::Boolean(true),
        )
        .encode(1);
        for cut in 0..r.len() {
            let _ = Pdu::decode(&r[..cut]);
        }
        let mut w = Writer::new();
        w.constructed(Tag::ctx_c(1), |w| {
            w.integer(Tag::INTEGER, 1);
            w.constructed(Tag::ctx_c(4), |w| {
                w.constructed(Tag::ctx_c(1), |w| Data::Float(1.0).encode(w))
            })
        });
        for cut in 0..w.buf.len() {
            assert!(Pdu::decode(&w.buf[..cut]).is_err(), "cut {cut}");
        }
    }
}
