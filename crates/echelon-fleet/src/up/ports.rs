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
    /// Router topology: site `s`'s router endpoint at `s`.
    pub(super) routers: Vec<String>,
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
            routers,
            ports,
        })
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
