//! What the exports to lighting desks (Eos, grandMA3) share: the `address` key of their
//! config sections, and a UDP socket to send from.

use std::net::{Ipv4Addr, Ipv6Addr, SocketAddr, UdpSocket};

/// A desk's `address` key: None when empty (that export is off), Err naming `key` when
/// it is not an address:port such as `example`.
pub fn address(key: &str, value: &str, example: &str) -> Result<Option<SocketAddr>, String> {
    if value.trim().is_empty() {
        return Ok(None);
    }
    value
        .trim()
        .parse()
        .map(Some)
        .map_err(|_| format!("{key} `{value}` is not an address:port such as {example}"))
}

/// A socket of the right family to send to `to` from any local port.
pub fn udp_socket(to: SocketAddr) -> Result<UdpSocket, String> {
    let local: SocketAddr = if to.is_ipv4() {
        (Ipv4Addr::UNSPECIFIED, 0).into()
    } else {
        (Ipv6Addr::UNSPECIFIED, 0).into()
    };
    UdpSocket::bind(local).map_err(|e| format!("cannot open a socket to send to {to}: {e}"))
}
