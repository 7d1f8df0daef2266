//! `output.modbus.allow`: the addresses and CIDR ranges the Modbus TCP server accepts connections
//! from (empty = everyone). Others are closed at accept and counted.

use std::net::IpAddr;

/// One address (`192.168.1.20`) or range (`192.168.1.0/24`, `fd00::/8`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct IpRange {
    net: IpAddr,
    prefix: u8,
}

impl std::str::FromStr for IpRange {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        let (addr, prefix) = match s.split_once('/') {
            Some((a, p)) => (a, Some(p)),
            None => (s, None),
        };
        let net: IpAddr = addr.trim().parse().map_err(|_| format!("{s:?} is not an IP address or CIDR range"))?;
        let net = net.to_canonical();
        let max = if net.is_ipv4() { 32 } else { 128 };
        let prefix = match prefix {
            None => max,
            Some(p) => match p.trim().parse::<u8>() {
                Ok(p) if p <= max => p,
                _ => return Err(format!("{s:?}: prefix length must be 0..={max}")),
            },
        };
        Ok(Self { net, prefix })
    }
}

impl IpRange {
    /// Whether `ip` is inside the range (an IPv4-mapped IPv6 address counts as IPv4).
    pub fn contains(&self, ip: IpAddr) -> bool {
        match (self.net, ip.to_canonical()) {
            (IpAddr::V4(n), IpAddr::V4(a)) => {
                mask_eq(u128::from(n.to_bits()), u128::from(a.to_bits()), 32, self.prefix)
            }
            (IpAddr::V6(n), IpAddr::V6(a)) => mask_eq(n.to_bits(), a.to_bits(), 128, self.prefix),
            _ => false,
        }
    }
}

fn mask_eq(a: u128, b: u128, bits: u32, prefix: u8) -> bool {
    let shift = bits - u32::from(prefix);
    shift >= bits || (a >> shift) == (b >> shift)
}

/// Whether a server listening on `listen` (HOST:PORT) with the allow list `allow` accepts every
/// address that can reach it: `allow` empty and `listen` not a loopback address. A host name other
/// than `localhost` counts as reachable from the network.
pub fn open_to_all(listen: &str, allow: &[String]) -> bool {
    if !allow.is_empty() || listen.is_empty() {
        return false;
    }
    let host = listen.rsplit_once(':').map_or(listen, |(h, _)| h);
    let host = host.trim_start_matches('[').trim_end_matches(']');
    match host.parse::<IpAddr>() {
        Ok(ip) => !ip.to_canonical().is_loopback(),
        Err(_) => !host.eq_ignore_ascii_case("localhost"),
    }
}

/// The allow list; empty allows everyone.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct AllowList(pub Vec<IpRange>);

impl AllowList {
    /// Parses the config entries; the first bad one is the error.
    pub fn parse(entries: &[String]) -> Result<Self, String> {
        entries.iter().map(|e| e.parse()).collect::<Result<Vec<_>, _>>().map(Self)
    }

    /// A list no TCP peer matches (the limited broadcast address only).
    pub fn nobody() -> Self {
        Self(vec![IpRange { net: IpAddr::V4(std::net::Ipv4Addr::BROADCAST), prefix: 32 }])
    }

    /// Whether a peer at `ip` may connect.
    pub fn permits(&self, ip: IpAddr) -> bool {
        self.0.is_empty() || self.0.iter().any(|r| r.contains(ip))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ip(s: &str) -> IpAddr {
        s.parse().unwrap_or(IpAddr::V4(std::net::Ipv4Addr::UNSPECIFIED))
    }

    #[test]
    fn ranges_and_addresses() {
        let l = AllowList::parse(&["192.168.1.0/24".into(), "10.0.0.7".into(), "fd00::/8".into()]).expect("valid");
        assert!(l.permits(ip("192.168.1.200")));
        assert!(l.permits(ip("::ffff:192.168.1.3")), "v4-mapped");
        assert!(!l.permits(ip("192.168.2.1")));
        assert!(l.permits(ip("10.0.0.7")));
        assert!(!l.permits(ip("10.0.0.8")));
        assert!(l.permits(ip("fd12::1")));
        assert!(!l.permits(ip("fe80::1")));
        assert!(AllowList::default().permits(ip("8.8.8.8")));
        assert!(AllowList::parse(&["0.0.0.0/0".into()]).expect("valid").permits(ip("8.8.8.8")));
        for bad in ["192.168.1.0/33", "plc.local", "300.1.1.1", "10.0.0.1/x", ""] {
            assert!(AllowList::parse(&[bad.into()]).is_err(), "{bad}");
        }
    }

    #[test]
    fn open_to_all_only_off_loopback_without_a_list() {
        for open in ["0.0.0.0:502", "192.168.1.5:502", "[::]:9464", "box.local:502"] {
            assert!(open_to_all(open, &[]), "{open}");
            assert!(!open_to_all(open, &["192.168.1.20".into()]), "{open} with a list");
        }
        for closed in ["127.0.0.1:5020", "[::1]:9464", "localhost:9464", ""] {
            assert!(!open_to_all(closed, &[]), "{closed}");
        }
    }
}
