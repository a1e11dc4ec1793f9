//! Loopback ports for the routers and processes, and the links between
//! them ([`Links`]).

use std::net::{TcpListener, UdpSocket};

use crate::FleetError;

use super::{Topology, UpOptions};

/// Free loopback ports for a Zenoh link protocol: UDP ports for QUIC, else
/// TCP ports.
pub fn free_ports_for(proto: &str, n: usize) -> Result<Vec<u16>, FleetError> {
    match proto {
        "quic" => held_ports(n, "UDP", || {
            let socket = UdpSocket::bind("127.0.0.1:0")?;
            Ok((socket.local_addr()?.port(), socket))
        }),
        _ => free_ports(n),
    }
}

/// Free loopback TCP ports (bound then released: each is free right now).
pub fn free_ports(n: usize) -> Result<Vec<u16>, FleetError> {
    held_ports(n, "TCP", || {
        let listener = TcpListener::bind("127.0.0.1:0")?;
        Ok((listener.local_addr()?.port(), listener))
    })
}

/// `n` ports from `bind`, all bound at once (so they differ), released on
/// return.
fn held_ports<S>(
    n: usize,
    kind: &str,
    bind: impl Fn() -> std::io::Result<(u16, S)>,
) -> Result<Vec<u16>, FleetError> {
    let held = (0..n)
        .map(|_| bind())
        .collect::<Result<Vec<_>, _>>()
        .map_err(|e| FleetError::Config(format!("no free loopback {kind} port: {e}")))?;
    Ok(held.into_iter().map(|(port, _)| port).collect())
}

/// How `fleet up`'s processes link: the routers' endpoints (router topology)
/// or every process's own port (mesh).
pub(super) struct Links {
    pub(super) topology: Topology,
    pub(super) proto: &'static str,
    /// Router topology: site `s`'s router endpoint at `s` (where the
    /// hub's own processes connect).
    pub(super) routers: Vec<String>,
    /// Router topology: what site `s`'s router listens on (its endpoint;
    /// a hub's, those given to `--listen`).
    pub(super) listen: Vec<Vec<String>>,
    /// Mesh: process `i`'s port at `i`.
    pub(super) ports: Vec<u16>,
}

impl Links {
    pub(super) fn new(
        opts: &UpOptions,
        proto: &'static str,
        processes: usize,
    ) -> Result<Links, FleetError> {
        let (routers, ports) = match opts.topology {
            Topology::Router if opts.hub.is_some() => {
                let hub = opts
                    .hub
                    .as_ref()
                    .map(|h| h.listen.clone())
                    .unwrap_or_default();
                let local = hub.first().map(|e| local_endpoint(e)).unwrap_or_default();
                return Ok(Links {
                    topology: opts.topology,
                    proto,
                    routers: vec![local],
                    listen: vec![hub],
                    ports: Vec::new(),
                });
            }
            Topology::Router => {
                let ports = free_ports_for(proto, opts.sites)?;
                let routers = ports
                    .iter()
                    .map(|p| format!("{proto}/127.0.0.1:{p}"))
                    .collect();
                (routers, Vec::new())
            }
            Topology::Mesh => (Vec::new(), free_ports_for(proto, processes)?),
        };
        Ok(Links {
            topology: opts.topology,
            proto,
            listen: routers.iter().map(|r: &String| vec![r.clone()]).collect(),
            routers,
            ports,
        })
    }

    /// Process `i`'s session (of site `site`, from 0), as a robot file
    /// says it.
    pub(super) fn net_section(&self, i: usize, site: usize) -> crate::robot::NetSection {
        match self.topology {
            Topology::Router => crate::robot::NetSection {
                mode: crate::robot::NetMode::Client,
                connect: vec![self.routers[site].clone()],
                listen: Vec::new(),
                zenoh_config: None,
            },
            Topology::Mesh => crate::robot::NetSection {
                mode: crate::robot::NetMode::Peer,
                connect: (0..i).map(|j| self.peer(j)).collect(),
                listen: vec![self.peer(i)],
                zenoh_config: None,
            },
        }
    }

    /// Mesh: process `i`'s endpoint.
    pub(super) fn peer(&self, i: usize) -> String {
        format!("{}/127.0.0.1:{}", self.proto, self.ports[i])
    }

    /// The Zenoh arguments of process `i` (of site `site`, from 0).
    pub(super) fn args(&self, i: usize, site: usize) -> Vec<String> {
        match self.topology {
            Topology::Router => vec![
                "--mode".to_owned(),
                "client".to_owned(),
                "--connect".to_owned(),
                self.routers[site].clone(),
            ],
            Topology::Mesh => {
                let mut a = vec!["--listen".to_owned(), self.peer(i)];
                for j in 0..i {
                    a.extend(["--connect".to_owned(), self.peer(j)]);
                }
                a
            }
        }
    }
}

/// Where a process on the hub's own computer reaches a router listening on
/// `listen`: the same endpoint, an unspecified address (`0.0.0.0`, `[::]`)
/// replaced by loopback.
pub(super) fn local_endpoint(listen: &str) -> String {
    listen
        .replacen("/0.0.0.0:", "/127.0.0.1:", 1)
        .replacen("/[::]:", "/[::1]:", 1)
}

/// Why nothing can listen on the endpoint `listen` now (its address and
/// port already taken, for its protocol's transport: UDP for QUIC and UDP,
/// else TCP), or `None` when it is free (or cannot be told: the router
/// says why when it starts).
pub(super) fn taken(listen: &str) -> Option<String> {
    use std::net::ToSocketAddrs;
    let (proto, address) = echelon::scenario::endpoint_address(listen)?;
    let at = address.to_socket_addrs().ok()?.next()?;
    let (kind, protocol) = match proto {
        "quic" | "udp" => (socket2::Type::DGRAM, socket2::Protocol::UDP),
        _ => (socket2::Type::STREAM, socket2::Protocol::TCP),
    };
    // As a listener binds (SO_REUSEADDR: a hub's own connections waiting
    // out TIME_WAIT do not hold the port).
    let bound = socket2::Socket::new(socket2::Domain::for_address(at), kind, Some(protocol))
        .and_then(|s| {
            s.set_reuse_address(true)?;
            s.bind(&at.into())
        });
    match bound {
        Err(e) if e.kind() == std::io::ErrorKind::AddrInUse => Some(format!("{at} is in use")),
        Err(e) if e.kind() == std::io::ErrorKind::AddrNotAvailable => {
            Some(format!("{at} is not an address of this machine"))
        }
        _ => None,
    }
}
