//! Serving behind a reverse proxy: the `[server]` settings `public_origin`,
//! `trusted_proxies`, `forwarded_header` and `base_path`, their parsing and
//! normal forms. The web layer uses them to find the real client and to
//! check origins; the validation reports a bad value at its place in the
//! file.

use std::net::IpAddr;

/// A block of addresses (`10.0.0.0/8`, `::1/128`); a bare address is the
/// block of that one address.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Cidr {
    network: IpAddr,
    prefix: u8,
}

impl Cidr {
    /// Parses `ADDRESS/PREFIX` or `ADDRESS`. Host bits set below the prefix
    /// (`10.0.0.1/8`) are refused: they usually mean a typo in the prefix.
    pub fn parse(text: &str) -> Result<Cidr, String> {
        let text = text.trim();
        let (addr, prefix) = match text.split_once('/') {
            Some((a, p)) => (a, Some(p)),
            None => (text, None),
        };
        let network: IpAddr = addr
            .parse()
            .map_err(|_| format!("'{addr}' is not an IP address"))?;
        let max = if network.is_ipv4() { 32 } else { 128 };
        let prefix = match prefix {
            None => max,
            Some(p) => match p.parse::<u8>() {
                Ok(n) if n <= max && p.bytes().all(|b| b.is_ascii_digit()) => n,
                _ => return Err(format!("'/{p}' is not a prefix length of 0 to {max}")),
            },
        };
        let cidr = Cidr { network, prefix };
        if cidr.mask(network) != network {
            return Err(format!(
                "'{text}' has address bits set past the /{prefix} (did you mean {}/{prefix}?)",
                cidr.mask(network)
            ));
        }
        Ok(cidr)
    }

    /// Whether `ip` lies in this block. An IPv4 address mapped into IPv6
    /// (`::ffff:10.1.2.3`, as a dual-stack socket reports it) counts as the
    /// IPv4 address.
    pub fn contains(&self, ip: IpAddr) -> bool {
        let ip = ip.to_canonical();
        ip.is_ipv4() == self.network.is_ipv4() && self.mask(ip) == self.network
    }

    fn mask(&self, ip: IpAddr) -> IpAddr {
        match ip {
            IpAddr::V4(v4) => {
                let bits = u32::from(v4);
                let mask = u32::MAX
                    .checked_shl(32 - u32::from(self.prefix))
                    .unwrap_or(0);
                IpAddr::from((bits & mask).to_be_bytes())
            }
            IpAddr::V6(v6) => {
                let bits = u128::from(v6);
                let mask = u128::MAX
                    .checked_shl(128 - u32::from(self.prefix))
                    .unwrap_or(0);
                IpAddr::from((bits & mask).to_be_bytes())
            }
        }
    }
}

impl std::fmt::Display for Cidr {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}/{}", self.network, self.prefix)
    }
}

/// Which header a trusted proxy names the client (and its scheme) in
/// (`[server] forwarded_header`). Only that one is read: a proxy passes the
/// other one through from the client untouched, so believing it would let
/// the client choose its own address.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum ForwardedHeader {
    /// `X-Forwarded-For`, with `X-Forwarded-Proto` for the scheme (what
    /// nginx, HAProxy and most load balancers set).
    #[default]
    XForwardedFor,
    /// RFC 7239 `Forwarded`, its `for=` and `proto=`.
    Forwarded,
}

impl ForwardedHeader {
    /// `x-forwarded-for` or `forwarded`, in any case (header names are).
    pub fn parse(text: &str) -> Result<ForwardedHeader, String> {
        let t = text.trim();
        if t.eq_ignore_ascii_case("x-forwarded-for") {
            Ok(ForwardedHeader::XForwardedFor)
        } else if t.eq_ignore_ascii_case("forwarded") {
            Ok(ForwardedHeader::Forwarded)
        } else {
            Err(format!(
                "'{t}' is not a forwarding header; write \"x-forwarded-for\" or \"forwarded\", the one your proxy sets"
            ))
        }
    }

    /// The setting's value as written in the file.
    pub fn name(self) -> &'static str {
        match self {
            ForwardedHeader::XForwardedFor => "x-forwarded-for",
            ForwardedHeader::Forwarded => "forwarded",
        }
    }
}

/// The normal form of a `base_path`: `""` for the root, otherwise
/// `/seg[/seg…]` without a trailing slash. Segments are letters, digits and
/// `-._~`, so the path needs no escaping in URLs, cookies or HTML.
pub fn normal_base_path(text: &str) -> Result<String, String> {
    let trimmed = text.trim();
    if trimmed.is_empty() || trimmed == "/" {
        return Ok(String::new());
    }
    let Some(rest) = trimmed.strip_prefix('/') else {
        return Err(format!("'{trimmed}' must start with / (like /scada)"));
    };
    let rest = rest.strip_suffix('/').unwrap_or(rest);
    for seg in rest.split('/') {
        if seg.is_empty() || seg == "." || seg == ".." {
            return Err(format!(
                "'{trimmed}' has an empty, '.' or '..' segment; write it like /scada or /site/scada"
            ));
        }
        if let Some(c) = seg
            .chars()
            .find(|c| !(c.is_ascii_alphanumeric() || "-._~".contains(*c)))
        {
            return Err(format!(
                "'{trimmed}': the character '{c}' is not allowed; use letters, digits and - . _ ~"
            ));
        }
    }
    Ok(format!("/{rest}"))
}

/// The normal form of a `public_origin`: `scheme://host[:port]`, lower case,
/// the port left out when it is the scheme's default (as browsers send
/// `Origin`). No path, query, fragment or user info.
pub fn normal_public_origin(text: &str) -> Result<String, String> {
    let t = text.trim();
    let (scheme, rest) = if let Some(r) = t.strip_prefix("https://") {
        ("https", r)
    } else if let Some(r) = t.strip_prefix("http://") {
        ("http", r)
    } else {
        return Err(format!(
            "'{t}' must start with https:// or http:// (like https://scada.example.com)"
        ));
    };
    let rest = rest.strip_suffix('/').unwrap_or(rest);
    if rest.is_empty() {
        return Err(format!("'{t}' names no host"));
    }
    if let Some(c) = rest.chars().find(|c| "/?#@ \\".contains(*c)) {
        return Err(format!(
            "'{t}': an origin is scheme, host and port only ('{c}' found); a sub-path goes in [server] base_path"
        ));
    }
    let (host, port) = split_host_port(rest).ok_or_else(|| format!("'{t}' has a bad port"))?;
    let host_ok = if let Some(v6) = host.strip_prefix('[').and_then(|h| h.strip_suffix(']')) {
        v6.parse::<std::net::Ipv6Addr>().is_ok()
    } else {
        !host.is_empty()
            && host
                .chars()
                .all(|c| c.is_ascii_alphanumeric() || c == '-' || c == '.')
    };
    if !host_ok {
        return Err(format!("'{t}': '{host}' is not a host name or address"));
    }
    let default = if scheme == "https" { 443 } else { 80 };
    let host = host.to_ascii_lowercase();
    Ok(match port {
        Some(p) if p != default => format!("{scheme}://{host}:{p}"),
        _ => format!("{scheme}://{host}"),
    })
}

/// The host of a normal public origin, without port or brackets.
pub fn origin_host(origin: &str) -> &str {
    let rest = origin.split_once("://").map_or(origin, |(_, r)| r);
    let (host, _) = split_host_port(rest).unwrap_or((rest, None));
    host.trim_start_matches('[').trim_end_matches(']')
}

/// `host[:port]` or `[v6][:port]` into host and port; `None` for a bad port.
fn split_host_port(s: &str) -> Option<(&str, Option<u16>)> {
    let (host, port) = if s.starts_with('[') {
        let end = s.find(']')?;
        match &s[end + 1..] {
            "" => (&s[..=end], None),
            p => (&s[..=end], Some(p.strip_prefix(':')?)),
        }
    } else {
        match s.rsplit_once(':') {
            Some((h, p)) => (h, Some(p)),
            None => (s, None),
        }
    };
    match port {
        None => Some((host, None)),
        Some(p) if !p.is_empty() && p.bytes().all(|b| b.is_ascii_digit()) => {
            Some((host, Some(p.parse().ok().filter(|p| *p > 0)?)))
        }
        Some(_) => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cidrs_parse_and_match() {
        let lo = Cidr::parse("127.0.0.1/32").unwrap();
        assert!(lo.contains("127.0.0.1".parse().unwrap()));
        assert!(!lo.contains("127.0.0.2".parse().unwrap()));
        // A dual-stack socket's view of an IPv4 peer.
        assert!(lo.contains("::ffff:127.0.0.1".parse().unwrap()));
        let ten = Cidr::parse("10.0.0.0/8").unwrap();
        assert!(ten.contains("10.255.1.2".parse().unwrap()));
        assert!(!ten.contains("11.0.0.1".parse().unwrap()));
        assert!(!ten.contains("::1".parse().unwrap()));
        let v6 = Cidr::parse("fd00::/8").unwrap();
        assert!(v6.contains("fd12::1".parse().unwrap()));
        assert!(!v6.contains("10.0.0.1".parse().unwrap()));
        assert!(Cidr::parse("::1/128")
            .unwrap()
            .contains("::1".parse().unwrap()));
        assert!(Cidr::parse("0.0.0.0/0")
            .unwrap()
            .contains("8.8.8.8".parse().unwrap()));
        assert_eq!(
            Cidr::parse("192.168.1.7").unwrap().to_string(),
            "192.168.1.7/32"
        );
    }

    #[test]
    fn bad_cidrs_say_why() {
        for (bad, why) in [
            ("10.0.0.1/8", "did you mean 10.0.0.0/8"),
            ("10.0.0.0/33", "0 to 32"),
            ("::1/129", "0 to 128"),
            ("10.0.0.0/", "prefix length"),
            ("10.0.0.0/+8", "prefix length"),
            ("localhost", "not an IP address"),
            ("10.0.0/8", "not an IP address"),
            ("", "not an IP address"),
        ] {
            let e = Cidr::parse(bad).unwrap_err();
            assert!(e.contains(why), "{bad}: {e}");
        }
    }

    #[test]
    fn forwarded_headers_parse() {
        assert_eq!(
            ForwardedHeader::parse("x-forwarded-for"),
            Ok(ForwardedHeader::XForwardedFor)
        );
        assert_eq!(
            ForwardedHeader::parse(" Forwarded "),
            Ok(ForwardedHeader::Forwarded)
        );
        assert_eq!(ForwardedHeader::default().name(), "x-forwarded-for");
        for bad in ["", "x-forwarded-proto", "x-real-ip", "forwarded-for"] {
            let e = ForwardedHeader::parse(bad).unwrap_err();
            assert!(
                e.contains("\"x-forwarded-for\" or \"forwarded\""),
                "{bad}: {e}"
            );
        }
    }

    #[test]
    fn base_paths_normalise() {
        assert_eq!(normal_base_path("").unwrap(), "");
        assert_eq!(normal_base_path("/").unwrap(), "");
        assert_eq!(normal_base_path("/scada").unwrap(), "/scada");
        assert_eq!(normal_base_path("/scada/").unwrap(), "/scada");
        assert_eq!(normal_base_path("/site-1/scada").unwrap(), "/site-1/scada");
        for bad in [
            "scada", "/a//b", "/a/../b", "/sc ada", "/scada?x", "/é", "//",
        ] {
            assert!(normal_base_path(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn public_origins_normalise() {
        let ok = |s| normal_public_origin(s).unwrap();
        assert_eq!(ok("https://SCADA.example.com"), "https://scada.example.com");
        assert_eq!(
            ok("https://scada.example.com/"),
            "https://scada.example.com"
        );
        assert_eq!(
            ok("https://scada.example.com:443"),
            "https://scada.example.com"
        );
        assert_eq!(
            ok("http://scada.example.com:80"),
            "http://scada.example.com"
        );
        assert_eq!(
            ok("https://scada.example.com:8443"),
            "https://scada.example.com:8443"
        );
        assert_eq!(ok("http://127.0.0.1:8081"), "http://127.0.0.1:8081");
        assert_eq!(ok("https://[::1]:8443"), "https://[::1]:8443");
        assert_eq!(origin_host("https://[::1]:8443"), "::1");
        assert_eq!(
            origin_host("https://scada.example.com"),
            "scada.example.com"
        );
        for bad in [
            "scada.example.com",
            "ftp://scada.example.com",
            "https://",
            "https://scada.example.com/scada",
            "https://scada.example.com?x=1",
            "https://user@scada.example.com",
            "https://scada.example.com:0",
            "https://scada.example.com:99999",
            "https://scada.example.com:x",
            "https://[zz]:1",
            "https://sc_ada.example.com",
        ] {
            assert!(normal_public_origin(bad).is_err(), "{bad}");
        }
    }
}
