//! Who the client really is, behind a reverse proxy.
//!
//! The TCP peer of a proxied request is the proxy. When, and only when, that
//! peer is one of `[server] trusted_proxies`, the one header named by
//! `[server] forwarded_header` is believed: `X-Forwarded-For` with
//! `X-Forwarded-Proto` (the default), or RFC 7239 `Forwarded` with its
//! `proto=`. The other header is never read, whoever sends it: a proxy that
//! sets one passes the other through from the client, so guessing which
//! one to believe let a client choose its own address. The chain of
//! addresses is walked from the right (the hop nearest to us), skipping
//! trusted proxies, and the first address that is not one is the client.
//! Anything to the left of it was written by the client itself and may be
//! forged. From any other peer the headers are ignored.
//!
//! The answer is worked out once per request, by [`client_info`], and put
//! into the request's extensions as a [`ClientInfo`] for login throttling,
//! `/metrics`, live-socket caps, audit records and logs. A header that does
//! not parse is not believed at all: the client is then the peer.

use std::net::{IpAddr, Ipv4Addr, SocketAddr};
use std::sync::Arc;

use axum::extract::{ConnectInfo, Request, State};
use axum::http::{HeaderMap, HeaderName};
use axum::middleware::Next;
use axum::response::Response;
use gridscada_config::{Cidr, ForwardedHeader};

/// The real client of a request.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ClientInfo {
    /// The client's address: the TCP peer, or the address a trusted proxy
    /// reports.
    pub ip: IpAddr,
    /// A trusted proxy says the client reached it over HTTPS. (The server's
    /// own TLS is a separate flag: cookies are `Secure` when either holds.)
    pub https: bool,
}

/// At most this many hops of a forwarding chain are looked at (the nearest
/// ones); a longer chain is someone's attempt to make us work.
const MAX_HOPS: usize = 32;

/// The proxies whose forwarding header is believed, and which header that
/// is.
#[derive(Debug, Clone, Default)]
pub struct TrustedProxies {
    blocks: Vec<Cidr>,
    header: ForwardedHeader,
}

impl TrustedProxies {
    pub fn new(blocks: Vec<Cidr>, header: ForwardedHeader) -> Self {
        TrustedProxies { blocks, header }
    }

    /// The proxies and header of `[server]`.
    pub fn of_server(server: &gridscada_config::ServerConfig) -> Self {
        TrustedProxies::new(server.trusted_proxies(), server.forwarded_header())
    }

    pub fn trusts(&self, ip: IpAddr) -> bool {
        self.blocks.iter().any(|b| b.contains(ip))
    }

    /// The client of a request that came from `peer` with `headers`.
    pub fn client(&self, peer: IpAddr, headers: &HeaderMap) -> ClientInfo {
        let peer = peer.to_canonical();
        let direct = ClientInfo {
            ip: peer,
            https: false,
        };
        if !self.trusts(peer) {
            return direct;
        }
        let hops = match self.header {
            ForwardedHeader::Forwarded => {
                if !headers.contains_key(&FORWARDED) {
                    return direct;
                }
                joined(headers, &FORWARDED).and_then(|v| parse_forwarded(&v))
            }
            ForwardedHeader::XForwardedFor => {
                let protos = joined(headers, &X_FORWARDED_PROTO);
                if !headers.contains_key(&X_FORWARDED_FOR) {
                    // A proxy that reports only the scheme (the client is
                    // the proxy itself, or it hides the client).
                    let proto = protos.as_deref().and_then(|p| p.rsplit(',').next());
                    return ClientInfo {
                        ip: peer,
                        https: proto.is_some_and(|p| p.trim().eq_ignore_ascii_case("https")),
                    };
                }
                joined(headers, &X_FORWARDED_FOR)
                    .and_then(|v| parse_x_forwarded(&v, protos.as_deref()))
            }
        };
        let Some(hops) = hops else {
            tracing::debug!(%peer, "unreadable forwarding header from a trusted proxy; using the peer");
            return direct;
        };
        self.pick(&hops).unwrap_or(direct)
    }

    /// Walks `hops` (client first, nearest proxy last) from the right past
    /// trusted proxies. `None` when a hop that matters cannot be identified.
    fn pick(&self, hops: &[Hop]) -> Option<ClientInfo> {
        let hops = &hops[hops.len().saturating_sub(MAX_HOPS)..];
        // The nearest proxy's word on the scheme, for hops that carry none.
        let nearest_proto = hops.iter().rev().find_map(|h| h.https);
        for (i, hop) in hops.iter().enumerate().rev() {
            let ip = hop.node?;
            if !self.trusts(ip) || i == 0 {
                return Some(ClientInfo {
                    ip,
                    https: hop.https.or(nearest_proto).unwrap_or(false),
                });
            }
        }
        None
    }
}

static FORWARDED: HeaderName = HeaderName::from_static("forwarded");
static X_FORWARDED_FOR: HeaderName = HeaderName::from_static("x-forwarded-for");
static X_FORWARDED_PROTO: HeaderName = HeaderName::from_static("x-forwarded-proto");

/// All lines of a header joined by commas (HTTP's rule for list headers);
/// `None` when one is not text.
fn joined(headers: &HeaderMap, name: &HeaderName) -> Option<String> {
    let mut out = String::new();
    for v in headers.get_all(name) {
        if !out.is_empty() {
            out.push(',');
        }
        out.push_str(v.to_str().ok()?);
    }
    Some(out)
}

/// One hop of a forwarding chain: the address it names (`None`: `unknown`
/// or an obfuscated name) and the scheme it reports, if any.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Hop {
    node: Option<IpAddr>,
    https: Option<bool>,
}

/// `Forwarded: for=192.0.2.60;proto=https, for="[2001:db8::1]:4711"`.
/// `None` if any element does not parse.
fn parse_forwarded(value: &str) -> Option<Vec<Hop>> {
    let mut hops = Vec::new();
    for element in split_quoted(value, ',') {
        if element.trim().is_empty() {
            continue;
        }
        let mut hop = Hop {
            node: None,
            https: None,
        };
        let mut has_for = false;
        for pair in split_quoted(element, ';') {
            let pair = pair.trim();
            if pair.is_empty() {
                continue;
            }
            let (name, value) = pair.split_once('=')?;
            let value = unquote(value.trim())?;
            match name.trim().to_ascii_lowercase().as_str() {
                "for" => {
                    if has_for {
                        return None;
                    }
                    has_for = true;
                    hop.node = node(&value)?;
                }
                "proto" => hop.https = Some(value.eq_ignore_ascii_case("https")),
                _ => {}
            }
        }
        // An element without `for=` says nothing about who sent it: the
        // chain cannot be followed through it.
        if !has_for {
            return None;
        }
        hops.push(hop);
    }
    (!hops.is_empty()).then_some(hops)
}

/// `X-Forwarded-For: client, proxy1` with `X-Forwarded-Proto: https[, http]`.
/// The schemes line up with the addresses when there are as many of them;
/// otherwise the last one (the nearest proxy's) counts for all.
fn parse_x_forwarded(fors: &str, protos: Option<&str>) -> Option<Vec<Hop>> {
    let protos: Vec<bool> = protos
        .map(|p| {
            p.split(',')
                .map(|s| s.trim())
                .filter(|s| !s.is_empty())
                .map(|s| s.eq_ignore_ascii_case("https"))
                .collect()
        })
        .unwrap_or_default();
    let addrs: Vec<&str> = fors
        .split(',')
        .map(str::trim)
        .filter(|s| !s.is_empty())
        .collect();
    let mut hops = Vec::with_capacity(addrs.len());
    for (i, a) in addrs.iter().enumerate() {
        let https = if protos.len() == addrs.len() {
            Some(protos[i])
        } else {
            protos.last().copied()
        };
        hops.push(Hop {
            node: node(a)?,
            https,
        });
    }
    (!hops.is_empty()).then_some(hops)
}

/// A node: `192.0.2.1`, `192.0.2.1:4711`, `[2001:db8::1]`,
/// `[2001:db8::1]:4711`, a bare IPv6 address (as X-Forwarded-For carries
/// it), `unknown` or an obfuscated `_name` (`Some(None)`). Anything else is
/// not a node (`None`).
fn node(text: &str) -> Option<Option<IpAddr>> {
    let t = text.trim();
    if t.eq_ignore_ascii_case("unknown")
        || (t.starts_with('_')
            && t.len() > 1
            && t[1..]
                .bytes()
                .all(|b| b.is_ascii_alphanumeric() || b"._-".contains(&b)))
    {
        return Some(None);
    }
    if let Some(rest) = t.strip_prefix('[') {
        let (addr, after) = rest.split_once(']')?;
        if !(after.is_empty() || valid_port(after.strip_prefix(':')?)) {
            return None;
        }
        return addr
            .parse::<std::net::Ipv6Addr>()
            .ok()
            .map(|a| Some(IpAddr::V6(a).to_canonical()));
    }
    if let Ok(ip) = t.parse::<IpAddr>() {
        return Some(Some(ip.to_canonical()));
    }
    let (addr, port) = t.rsplit_once(':')?;
    if !valid_port(port) {
        return None;
    }
    addr.parse::<Ipv4Addr>().ok().map(|a| Some(IpAddr::V4(a)))
}

/// A port number, or an obfuscated port (`_abc`).
fn valid_port(p: &str) -> bool {
    (!p.is_empty() && p.bytes().all(|b| b.is_ascii_digit()) && p.parse::<u16>().is_ok())
        || (p.len() > 1
            && p.starts_with('_')
            && p[1..]
                .bytes()
                .all(|b| b.is_ascii_alphanumeric() || b"._-".contains(&b)))
}

/// Splits at `sep` outside double quotes (a backslash escapes inside them).
fn split_quoted(s: &str, sep: char) -> Vec<&str> {
    let mut parts = Vec::new();
    let (mut start, mut quoted, mut escaped) = (0, false, false);
    for (i, c) in s.char_indices() {
        if escaped {
            escaped = false;
        } else if quoted && c == '\\' {
            escaped = true;
        } else if c == '"' {
            quoted = !quoted;
        } else if c == sep && !quoted {
            parts.push(&s[start..i]);
            start = i + c.len_utf8();
        }
    }
    parts.push(&s[start..]);
    parts
}

/// A token, or a quoted string with its escapes undone; `None` for an
/// unterminated quote.
fn unquote(v: &str) -> Option<String> {
    let Some(inner) = v.strip_prefix('"') else {
        return (!v.contains('"')).then(|| v.to_string());
    };
    let inner = inner.strip_suffix('"')?;
    let mut out = String::with_capacity(inner.len());
    let mut chars = inner.chars();
    while let Some(c) = chars.next() {
        match c {
            '\\' => out.push(chars.next()?),
            '"' => return None,
            c => out.push(c),
        }
    }
    Some(out)
}

/// Middleware: works out the request's [`ClientInfo`] once and puts it into
/// the request's extensions. Without a connection address (a test calling
/// the router directly) the peer is taken as `0.0.0.0`.
pub async fn client_info(
    State(proxies): State<Arc<TrustedProxies>>,
    mut req: Request,
    next: Next,
) -> Response {
    let peer = req
        .extensions()
        .get::<ConnectInfo<SocketAddr>>()
        .map_or(IpAddr::from([0, 0, 0, 0]), |c| c.0.ip());
    let client = proxies.client(peer, req.headers());
    req.extensions_mut().insert(client);
    next.run(req).await
}

#[cfg(test)]
mod tests {
    use super::*;
    use axum::http::HeaderValue;

    /// Proxies that name the client in `X-Forwarded-For` (the default).
    fn trusted(blocks: &[&str]) -> TrustedProxies {
        trusted_with(blocks, ForwardedHeader::XForwardedFor)
    }

    fn trusted_with(blocks: &[&str], header: ForwardedHeader) -> TrustedProxies {
        TrustedProxies::new(
            blocks.iter().map(|b| Cidr::parse(b).unwrap()).collect(),
            header,
        )
    }

    fn headers(pairs: &[(&str, &[u8])]) -> HeaderMap {
        let mut h = HeaderMap::new();
        for (k, v) in pairs {
            h.append(
                HeaderName::from_bytes(k.as_bytes()).unwrap(),
                HeaderValue::from_bytes(v).unwrap(),
            );
        }
        h
    }

    fn ip(s: &str) -> IpAddr {
        s.parse().unwrap()
    }

    fn client(t: &TrustedProxies, peer: &str, h: &[(&str, &[u8])]) -> (String, bool) {
        let c = t.client(ip(peer), &headers(h));
        (c.ip.to_string(), c.https)
    }

    fn at(ip: &str, https: bool) -> (String, bool) {
        (ip.to_string(), https)
    }

    #[test]
    fn headers_from_an_untrusted_peer_are_ignored() {
        let t = trusted(&["127.0.0.1/32"]);
        let forged = [
            ("x-forwarded-for", b"10.9.9.9".as_slice()),
            ("x-forwarded-proto", b"https"),
            ("forwarded", b"for=10.9.9.9;proto=https"),
        ];
        assert_eq!(client(&t, "127.0.0.5", &forged), at("127.0.0.5", false));
        // No trusted proxies at all: nobody's headers count.
        assert_eq!(
            client(&trusted(&[]), "127.0.0.1", &forged),
            at("127.0.0.1", false)
        );
    }

    #[test]
    fn x_forwarded_for_is_walked_from_the_right() {
        let t = trusted(&["127.0.0.1/32", "10.0.0.0/8"]);
        // nginx appending the client to what the client sent.
        let h = [("x-forwarded-for", b"6.6.6.6, 203.0.113.7".as_slice())];
        assert_eq!(client(&t, "127.0.0.1", &h), at("203.0.113.7", false));
        // Two trusted proxies in a row are skipped.
        let h = [
            (
                "x-forwarded-for",
                b"6.6.6.6, 203.0.113.7, 10.1.1.1".as_slice(),
            ),
            ("x-forwarded-proto", b"https"),
        ];
        assert_eq!(client(&t, "127.0.0.1", &h), at("203.0.113.7", true));
        // Split over two header lines: the same list.
        let h = [
            ("x-forwarded-for", b"6.6.6.6".as_slice()),
            ("x-forwarded-for", b"203.0.113.7, 10.1.1.1"),
        ];
        assert_eq!(client(&t, "127.0.0.1", &h), at("203.0.113.7", false));
        // Every hop trusted: the furthest one is the client.
        let h = [("x-forwarded-for", b"10.2.2.2, 10.1.1.1".as_slice())];
        assert_eq!(client(&t, "127.0.0.1", &h), at("10.2.2.2", false));
        // Ports and IPv6, bracketed or bare.
        let h = [(
            "x-forwarded-for",
            b"[2001:db8::1]:4711, 198.51.100.2:5000".as_slice(),
        )];
        assert_eq!(client(&t, "127.0.0.1", &h), at("198.51.100.2", false));
        let h = [("x-forwarded-for", b"2001:db8::7".as_slice())];
        assert_eq!(client(&t, "127.0.0.1", &h), at("2001:db8::7", false));
    }

    #[test]
    fn schemes_line_up_with_addresses_or_the_nearest_counts() {
        let t = trusted(&["127.0.0.1/32", "10.0.0.0/8"]);
        let h = [
            ("x-forwarded-for", b"203.0.113.7, 10.1.1.1".as_slice()),
            ("x-forwarded-proto", b"https, http"),
        ];
        assert_eq!(client(&t, "127.0.0.1", &h), at("203.0.113.7", true));
        let h = [
            ("x-forwarded-for", b"203.0.113.7, 10.1.1.1".as_slice()),
            ("x-forwarded-proto", b"HTTPS"),
        ];
        assert_eq!(client(&t, "127.0.0.1", &h), at("203.0.113.7", true));
        // Only the scheme: the client is the proxy itself.
        let h = [("x-forwarded-proto", b"https".as_slice())];
        assert_eq!(client(&t, "127.0.0.1", &h), at("127.0.0.1", true));
    }

    #[test]
    fn forwarded_rfc_7239() {
        let t = trusted_with(
            &["127.0.0.1/32", "::1/128", "10.0.0.0/8"],
            ForwardedHeader::Forwarded,
        );
        let f = |v: &[u8]| client(&t, "127.0.0.1", &[("forwarded", v)]);
        assert_eq!(
            f(b"for=192.0.2.60;proto=https;by=203.0.113.43"),
            at("192.0.2.60", true)
        );
        assert_eq!(
            f(br#"for="[2001:db8:cafe::17]:4711";proto=https"#),
            at("2001:db8:cafe::17", true)
        );
        assert_eq!(
            f(br#"For="[2001:db8::1]", for=10.0.0.2;proto=http"#),
            at("2001:db8::1", false)
        );
        assert_eq!(
            f(b"for=6.6.6.6, for=198.51.100.17:8080;proto=https, for=10.1.1.1"),
            at("198.51.100.17", true)
        );
        // The element's scheme is missing: the nearest proxy's counts.
        assert_eq!(
            f(b"for=198.51.100.17, for=10.1.1.1;proto=https"),
            at("198.51.100.17", true)
        );
        // Quoted commas and semicolons stay inside their value.
        assert_eq!(
            f(br#"for=198.51.100.17;ext="a,b;c", for=10.1.1.1"#),
            at("198.51.100.17", false)
        );
        // A dual-stack socket's IPv4 peer is the IPv4 address.
        let h = [("forwarded", b"for=192.0.2.60".as_slice())];
        assert_eq!(client(&t, "::ffff:127.0.0.1", &h), at("192.0.2.60", false));
    }

    #[test]
    fn only_the_named_header_is_read() {
        let blocks = ["127.0.0.1/32", "10.0.0.0/8"];
        let xff = trusted(&blocks);
        let fwd = trusted_with(&blocks, ForwardedHeader::Forwarded);
        // nginx behind the documented configuration: it sets X-Forwarded-For
        // and the client's own Forwarded passes through.
        let through_nginx = [
            ("x-forwarded-for", b"203.0.113.7".as_slice()),
            ("x-forwarded-proto", b"http"),
            ("forwarded", b"for=8.8.8.8;proto=https"),
        ];
        assert_eq!(
            client(&xff, "127.0.0.1", &through_nginx),
            at("203.0.113.7", false)
        );
        // The same request to a server told to read Forwarded.
        assert_eq!(
            client(&fwd, "127.0.0.1", &through_nginx),
            at("8.8.8.8", true)
        );
        // The other header alone says nothing, neither address nor scheme.
        let only_forwarded = [("forwarded", b"for=8.8.8.8;proto=https".as_slice())];
        assert_eq!(
            client(&xff, "127.0.0.1", &only_forwarded),
            at("127.0.0.1", false)
        );
        let only_x = [
            ("x-forwarded-for", b"8.8.8.8".as_slice()),
            ("x-forwarded-proto", b"https"),
        ];
        assert_eq!(client(&fwd, "127.0.0.1", &only_x), at("127.0.0.1", false));
        assert_eq!(
            client(&fwd, "127.0.0.1", &[("x-forwarded-proto", b"https")]),
            at("127.0.0.1", false)
        );
        // With Forwarded, the scheme is its proto= only.
        let h = [
            ("forwarded", b"for=203.0.113.7".as_slice()),
            ("x-forwarded-proto", b"https"),
        ];
        assert_eq!(client(&fwd, "127.0.0.1", &h), at("203.0.113.7", false));
        // An unreadable header of the other kind changes nothing.
        let h = [
            ("x-forwarded-for", b"203.0.113.7".as_slice()),
            ("forwarded", b"for=\"\\"),
        ];
        assert_eq!(client(&xff, "127.0.0.1", &h), at("203.0.113.7", false));
        let h = [
            ("forwarded", b"for=203.0.113.7".as_slice()),
            ("x-forwarded-for", b"garbage"),
        ];
        assert_eq!(client(&fwd, "127.0.0.1", &h), at("203.0.113.7", false));
    }

    #[test]
    fn unidentifiable_hops_and_malformed_headers_fall_back_to_the_peer() {
        let t = trusted(&["127.0.0.1/32", "10.0.0.0/8"]);
        let fwd = trusted_with(&["127.0.0.1/32", "10.0.0.0/8"], ForwardedHeader::Forwarded);
        let peer = at("127.0.0.1", false);
        for bad in [
            b"for=unknown".as_slice(),
            b"for=_hidden, for=10.1.1.1",
            b"for=\"[2001:db8::1]:4711",
            b"for=[2001:db8::1]:x",
            b"for=2001:db8::1]",
            b"for=192.0.2.60;for=192.0.2.61",
            b"proto=https",
            b"for",
            b"for=999.1.1.1",
            b"for=\"a\"b\"",
            b"",
            b",,,",
            b"for=192.0.2.60:99999",
            b"for=\"\\",
        ] {
            let got = client(&fwd, "127.0.0.1", &[("forwarded", bad)]);
            assert_eq!(got, peer, "Forwarded: {}", String::from_utf8_lossy(bad));
        }
        for bad in [
            b"unknown".as_slice(),
            b"not-an-ip, 203.0.113.7",
            b"203.0.113.7, garbage",
            b"",
            b" , ",
            b"203.0.113.7:",
            b"\xff\xfe",
        ] {
            let got = client(&t, "127.0.0.1", &[("x-forwarded-for", bad)]);
            assert_eq!(
                got,
                peer,
                "X-Forwarded-For: {}",
                String::from_utf8_lossy(bad)
            );
        }
        // A hop left of the client may be garbage: it is never looked at.
        let h = [("x-forwarded-for", b"6.6.6.6, 203.0.113.7".as_slice())];
        assert_eq!(client(&t, "127.0.0.1", &h), at("203.0.113.7", false));
    }

    #[test]
    fn a_long_chain_is_cut_to_its_nearest_hops() {
        let t = trusted(&["10.0.0.0/8"]);
        let mut chain = vec!["203.0.113.9".to_string()];
        chain.extend((0..1000).map(|i| format!("10.0.{}.{}", i / 250, i % 250)));
        let v = chain.join(", ");
        let got = client(&t, "10.0.0.1", &[("x-forwarded-for", v.as_bytes())]);
        // All 32 nearest hops are trusted: the furthest of them is taken.
        assert!(got.0.starts_with("10.0."), "{got:?}");
    }
}
