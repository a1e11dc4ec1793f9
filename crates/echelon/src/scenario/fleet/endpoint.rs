//! Zenoh endpoints as a robot's router is given: checked, and taken apart.

/// The link protocols a robot's router may be reached over: those echelon's
/// Zenoh is built with.
pub const ENDPOINT_PROTOCOLS: [&str; 4] = ["tcp", "udp", "tls", "quic"];

/// Checks a Zenoh endpoint as a robot's router is given:
/// `<protocol>/<host>:<port>` (a name, an IPv4 address or a bracketed IPv6
/// one), optionally followed by Zenoh's `?metadata` and `#config` parts,
/// which are passed on unchecked.
pub fn check_endpoint(e: &str) -> Result<(), String> {
    check_endpoint_from(e, 1)
}

/// Checks an endpoint to listen on: as [`check_endpoint`], and port 0 (any
/// free port) too.
pub fn check_listen_endpoint(e: &str) -> Result<(), String> {
    check_endpoint_from(e, 0)
}

/// A Zenoh endpoint's protocol and address (`tcp`, `192.168.1.2:7447`),
/// its `?metadata` and `#config` parts left out; `None` without a `/`. The
/// one place that takes an endpoint apart; [`endpoint_port`] its port.
pub fn endpoint_address(e: &str) -> Option<(&str, &str)> {
    e.split(['?', '#'])
        .next()
        .unwrap_or_default()
        .split_once('/')
}

/// An endpoint address's host and port as written (`192.168.1.2`, `7447`;
/// a bracketed IPv6 host keeps its brackets); `None` without a `:`.
pub fn endpoint_host_port(address: &str) -> Option<(&str, &str)> {
    address.rsplit_once(':')
}

/// An endpoint's port as written (`None`: no address or no port).
pub fn endpoint_port(e: &str) -> Option<&str> {
    endpoint_address(e)
        .and_then(|(_, a)| endpoint_host_port(a))
        .map(|(_, p)| p)
}

/// Checks `e` as [`check_endpoint`] says, with ports from `lowest`.
fn check_endpoint_from(e: &str, lowest: u16) -> Result<(), String> {
    let Some((proto, address)) = endpoint_address(e) else {
        return Err(format!(
            "`{e}` is not a Zenoh endpoint: give <protocol>/<host>:<port>, e.g. tcp/192.168.1.21:7447"
        ));
    };
    if !ENDPOINT_PROTOCOLS.contains(&proto) {
        return Err(format!(
            "`{e}`: the protocol must be one of {} (not `{proto}`)",
            ENDPOINT_PROTOCOLS.join(", ")
        ));
    }
    let bad = |why: &str| Err(format!("`{e}`: {why}; give <protocol>/<host>:<port>"));
    let Some((host, port)) = endpoint_host_port(address) else {
        return bad("no port");
    };
    if !matches!(port.parse::<u16>(), Ok(p) if p >= lowest) {
        return bad(&format!("`{port}` is not a port ({lowest} to 65535)"));
    }
    let host_ok = if let Some(v6) = host.strip_prefix('[').and_then(|h| h.strip_suffix(']')) {
        v6.parse::<std::net::Ipv6Addr>().is_ok()
    } else {
        !host.is_empty()
            && host.split('.').all(|label| {
                !label.is_empty()
                    && !label.starts_with('-')
                    && label
                        .bytes()
                        .all(|b| b.is_ascii_alphanumeric() || b == b'-')
            })
    };
    if !host_ok {
        return bad(&format!(
            "`{host}` is not a host name, an IPv4 address or a bracketed IPv6 address"
        ));
    }
    Ok(())
}
