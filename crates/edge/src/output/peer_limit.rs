//! The per-address connection limit both TCP servers apply (Modbus, [`super::tcp_conns`]; metrics,
//! [`crate::web`]): a few hosts holding connections open take a few slots, never all of
//! them. What a server does at the limit is its own: the Modbus server closes an older connection
//! of that address, the metrics endpoint refuses the new one.

use std::net::IpAddr;

/// At most this many connections open at once from one IP address.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PeerLimit {
    per_peer: usize,
}

impl PeerLimit {
    /// `max_per_peer` connections per address, at least 1 and at most `max_connections` (the total).
    pub fn new(max_per_peer: usize, max_connections: usize) -> Self {
        Self { per_peer: max_per_peer.clamp(1, max_connections.max(1)) }
    }

    /// Connections allowed from one address.
    pub fn get(self) -> usize {
        self.per_peer
    }

    /// Whether `ip` already has its share among the addresses of the connections open now.
    pub fn reached(self, ip: IpAddr, open: impl IntoIterator<Item = IpAddr>) -> bool {
        open.into_iter().filter(|&p| p == ip).count() >= self.per_peer
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn counts_one_address_and_never_exceeds_the_total() {
        let (a, b): (IpAddr, IpAddr) = ([10, 0, 0, 1].into(), [10, 0, 0, 2].into());
        let l = PeerLimit::new(2, 8);
        assert!(!l.reached(a, [a, b, b]));
        assert!(l.reached(a, [a, b, a]));
        assert_eq!(PeerLimit::new(4, 2).get(), 2, "at most the total");
        assert_eq!(PeerLimit::new(0, 0).get(), 1, "at least one");
    }
}
