//! What the exports to lighting desks (Eos, grandMA3) share: a UDP socket to send from
//! (their `address` keys are read by `crate::osc::address`).

use std::net::{Ipv4Addr, Ipv6Addr, SocketAddr, UdpSocket};

/// A socket of the right family to send to `to` from any local port.
pub fn udp_socket(to: SocketAddr) -> Result<UdpSocket, String> {
    let local: SocketAddr = if to.is_ipv4() {
        (Ipv4Addr::UNSPECIFIED, 0).into()
    } else {
        (Ipv6Addr::UNSPECIFIED, 0).into()
    };
    UdpSocket::bind(local).map_err(|e| format!("cannot open a socket to send to {to}: {e}"))
}
