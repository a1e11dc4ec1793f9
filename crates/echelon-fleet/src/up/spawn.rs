//! `fleet up`'s start: where each process sits and how it links
//! ([`Layout`]), what each is started with, `endpoints.json`, and the hub's
//! wait for its robots.

use std::path::{Path, PathBuf};
use std::time::Duration;

use echelon::scenario::{FleetSettings, Placement, Scenario};

use super::join;
use super::ports::Links;
use super::process::{Proc, poll_all, spawn};
use super::{
    ENDPOINTS_FILE, HubOptions, Topology, UpOptions, chaos_args, hosts, robots, router_role,
};
use crate::FleetError;
use crate::StopFlag;
use crate::role::{Member, Role};

/// What `fleet up` runs, checked against its options before anything is
/// written or starts.
pub(super) struct Planned {
    /// The scenario.
    pub(super) scenario: Scenario,
    /// Its `[fleet]` settings.
    pub(super) fleet: FleetSettings,
    /// The number of robots.
    pub(super) n: usize,
    /// The number of simulated ROS 2 bases (`--ros2` without `--real`: one
    /// per robot; else none).
    pub(super) bases: usize,
    /// Fleet time to run, s.
    pub(super) duration: f64,
    /// Robots per robot process ([`hosts::per_process`]).
    pub(super) per_process: usize,
}

/// The fleet's layout: the plan, the processes' links, and where their logs
/// go. Processes are numbered in start order: the collector at 0, the ROS 2
/// bases (with `--ros2`) at 1 … bases, the robots after them, the leader at
/// `leader_at`, the operator's heartbeat last; in a mesh also the order of
/// their ports.
pub(super) struct Layout<'a> {
    /// The options.
    pub(super) opts: &'a UpOptions,
    /// What runs.
    pub(super) plan: Planned,
    /// The leader's number.
    pub(super) leader_at: usize,
    /// How the processes link.
    pub(super) net: Links,
    /// Where each process's log and report go.
    pub(super) logs: PathBuf,
}

/// The fleet's processes but the leader, once started, declared in the
/// order they are dropped (each killed if still running): the reverse of
/// their start's.
pub(super) struct Procs {
    /// The robots' processes on the hub, in agent order: one robot each
    /// (`fleet robot`), or a host of several (`fleet host`).
    pub(super) robots: Vec<Proc>,
    /// The agents each of `robots` runs.
    pub(super) hosted: hosts::Groups,
    /// `fleet garbage`, when asked.
    pub(super) garbage: Option<Proc>,
    /// The operator's heartbeat, in a supervised run.
    pub(super) operator: Option<Proc>,
    /// The simulated ROS 2 bases, in agent order.
    pub(super) bases: Vec<Proc>,
    /// The collector.
    pub(super) collector: Proc,
    /// The routers, by site.
    pub(super) routers: Vec<Proc>,
    /// Each router's arguments (site 1's started again with them).
    pub(super) router_args: Vec<Vec<String>>,
    /// The agents of the robots on the hub (those of `robots`).
    pub(super) on_hub: Vec<u32>,
}

impl<'a> Layout<'a> {
    /// The layout of `plan`'s fleet as `opts` asks, its ports (mesh) or
    /// routers' endpoints chosen; logs under `logs`.
    pub(super) fn new(
        opts: &'a UpOptions,
        plan: Planned,
        logs: PathBuf,
    ) -> Result<Layout<'a>, FleetError> {
        let proto = crate::net::link_protocol(opts.secure.is_some());
        let leader_at = plan.bases + plan.n + 1;
        // The operator's heartbeat last, when the scenario asks for one.
        let net = Links::new(opts, proto, leader_at + 2)?;
        Ok(Layout {
            opts,
            plan,
            leader_at,
            net,
            logs,
        })
    }

    /// Robot `k`'s process number.
    pub(super) fn robot_at(&self, k: usize) -> usize {
        self.plan.bases + k
    }

    /// Process `i`'s site (router topology): robots and their bases
    /// round-robin, the collector and the leader on site 1.
    pub(super) fn site_of(&self, i: usize) -> usize {
        match i {
            0 => 0,
            i if i >= self.leader_at => 0,
            i => ((i - 1) % self.plan.n) % self.net.routers.len().max(1),
        }
    }

    /// The secure-mode arguments of a process of `identity` (none in plain
    /// mode).
    pub(super) fn secure_args(&self, identity: &str) -> Vec<String> {
        match &self.opts.secure {
            Some(dir) => vec![
                "--secure".to_owned(),
                dir.display().to_string(),
                "--identity".to_owned(),
                identity.to_owned(),
                "--robots".to_owned(),
                self.plan.n.to_string(),
            ],
            None => Vec::new(),
        }
    }

    /// The arguments every process `i` of `identity` takes: the fleet's
    /// name, its links, its certificates.
    pub(super) fn common(&self, i: usize, identity: &str) -> Vec<String> {
        let mut a = vec!["--fleet".to_owned(), self.plan.fleet.name.clone()];
        a.extend(self.net.args(i, self.site_of(i)));
        a.extend(self.secure_args(identity));
        a
    }

    /// `fleet ROLE SCENARIO` on the fleet's clock, to its end.
    pub(super) fn on_clock(&self, role: Role) -> Vec<String> {
        vec![
            "fleet".to_owned(),
            role.name().to_owned(),
            self.opts.scenario.clone(),
            "--duration".to_owned(),
            self.plan.duration.to_string(),
            "--time-scale".to_owned(),
            self.opts.time_scale.to_string(),
        ]
    }

    /// Starts a process as `role` with `args` and the environment `env`,
    /// its log and report under the layout's logs.
    pub(super) fn spawn(
        &self,
        role: &str,
        args: &[String],
        env: &[(&str, &str)],
    ) -> Result<Proc, FleetError> {
        spawn(&self.opts.exe, role, args, env, &self.logs)
    }

    /// Writes `endpoints.json`: where each process listens, for tools (or
    /// tests) that want to join; says where a hub listens.
    pub(super) fn write_endpoints(&self) -> Result<(), FleetError> {
        let opts = self.opts;
        let (n, bases, net) = (self.plan.n, self.plan.bases, &self.net);
        let mut endpoints = serde_json::Map::new();
        endpoints.insert(
            "topology".into(),
            serde_json::to_value(opts.topology).map_err(echelon_mcap::McapLogError::from)?,
        );
        match opts.topology {
            Topology::Router => {
                for (s, e) in net.routers.iter().enumerate() {
                    endpoints.insert(router_role(s + 1), e.clone().into());
                }
                if let Some(hub) = &opts.hub {
                    for (i, e) in hub.listen.iter().enumerate() {
                        let name = match i {
                            0 => "hub".to_owned(),
                            i => format!("hub/{}", i + 1),
                        };
                        endpoints.insert(name, e.clone().into());
                        eprintln!(
                            "fleet up: the hub listens on {e} (robots, fleet status/stop/resume: --hub {})",
                            e.replacen("/0.0.0.0:", "/<this machine's address>:", 1)
                        );
                    }
                }
            }
            Topology::Mesh => {
                endpoints.insert(Role::Collector.name().into(), net.peer(0).into());
                for k in 1..=n {
                    endpoints.insert(
                        Member::Robot(k as u32).liveliness(),
                        net.peer(self.robot_at(k)).into(),
                    );
                }
                for k in 1..=bases {
                    endpoints.insert(Member::Base(k as u32).liveliness(), net.peer(k).into());
                }
                endpoints.insert(Role::Leader.name().into(), net.peer(self.leader_at).into());
            }
        }
        if let Some(addr) = opts.foxglove {
            endpoints.insert("foxglove".into(), format!("ws://{addr}").into());
        }
        if let Some(addr) = opts.dashboard {
            endpoints.insert("dashboard".into(), format!("http://{addr}/").into());
        }
        crate::write_json_file(&opts.out.join(ENDPOINTS_FILE), &endpoints)
    }

    /// Each site's processes (by role), for the report.
    pub(super) fn sites(&self) -> Vec<Vec<String>> {
        let bases = self.plan.bases;
        let mut sites = vec![Vec::new(); self.net.routers.len()];
        for i in 0..=self.leader_at {
            let role = match i {
                0 => Role::Collector.name().to_owned(),
                i if i == self.leader_at => Role::Leader.name().to_owned(),
                i if i <= bases => Member::Base(i as u32).liveliness(),
                i => Member::Robot((i - bases) as u32).liveliness(),
            };
            if let Some(site) = sites.get_mut(self.site_of(i)) {
                site.push(role);
            }
        }
        sites
    }

    /// Starts the routers (router topology), each linked to those before
    /// it; returns them and their arguments (site 1's without the
    /// `--die-at` the fault matrix may give it).
    pub(super) fn spawn_routers(&self) -> Result<(Vec<Proc>, Vec<Vec<String>>), FleetError> {
        let (opts, net) = (self.opts, &self.net);
        let mut routers = Vec::with_capacity(net.routers.len());
        let mut router_args = Vec::with_capacity(net.routers.len());
        for s in 0..net.routers.len() {
            let mut args = vec!["fleet".to_owned(), Role::Router.name().to_owned()];
            if opts.ros2 {
                args.push(opts.scenario.clone());
            }
            for l in &net.listen[s] {
                args.extend(["--listen".to_owned(), l.clone()]);
            }
            for other in &net.routers[..s] {
                args.extend(["--connect".to_owned(), other.clone()]);
            }
            args.extend(self.secure_args(&Member::Router.identity()));
            let mut first = args.clone();
            if s == 0
                && let Some((at, _)) = opts.chaos.router_restart
            {
                first.extend(["--die-at".to_owned(), at.to_string()]);
            }
            routers.push(self.spawn(&router_role(s + 1), &first, &[])?);
            router_args.push(args);
        }
        Ok((routers, router_args))
    }

    /// Starts the collector, with the operator token in `token_env`.
    pub(super) fn spawn_collector(&self, token_env: &[(&str, &str)]) -> Result<Proc, FleetError> {
        let opts = self.opts;
        let mut args = vec![
            "fleet".to_owned(),
            Role::Collector.name().to_owned(),
            "--out".to_owned(),
            opts.out.display().to_string(),
            // For its trajectory.csv's columns (and, with --ros2, its topics).
            opts.scenario.clone(),
        ];
        // Real robots' ROS topics stay on their own routers, out of its reach.
        if opts.ros2 && !opts.real {
            args.push("--ros2".to_owned());
        }
        if let Some(addr) = opts.foxglove {
            args.extend(["--foxglove".to_owned(), addr.to_string()]);
        }
        if let Some(addr) = opts.dashboard {
            args.extend(["--dashboard".to_owned(), addr.to_string()]);
        }
        if let Some(hz) = opts.log_rate {
            args.extend(["--log-rate".to_owned(), hz.to_string()]);
        }
        args.extend(chaos_args(&opts.chaos, Member::Collector));
        args.extend(self.common(0, &Member::Collector.identity()));
        self.spawn(Role::Collector.name(), &args, token_env)
    }

    /// Starts the simulated ROS 2 bases (`--ros2` without `--real`), each
    /// with its hazards and faults.
    pub(super) fn spawn_bases(&self) -> Result<Vec<Proc>, FleetError> {
        let opts = self.opts;
        let bases = self.plan.bases;
        let mut base_procs = Vec::with_capacity(bases);
        for k in 1..=bases {
            let mut args = vec![
                "fleet".to_owned(),
                Role::Base.name().to_owned(),
                opts.scenario.clone(),
                "--ros2".to_owned(),
                "--agent".to_owned(),
                k.to_string(),
                "--time-scale".to_owned(),
                opts.time_scale.to_string(),
            ];
            for (_, w) in opts.hazards.iter().filter(|(j, _)| *j as usize == k) {
                args.extend(["--hazard".to_owned(), w.to_string()]);
            }
            args.extend(chaos_args(&opts.chaos, Member::Base(k as u32)));
            args.extend(self.common(k, &Member::Base(k as u32).identity()));
            base_procs.push(self.spawn(&Member::Base(k as u32).liveliness(), &args, &[])?);
        }
        Ok(base_procs)
    }

    /// A supervised run: starts the operator's heartbeat, on the hub (its
    /// death, or its machine asleep, holds the fleet within the deadline).
    pub(super) fn spawn_operator(&self) -> Result<Option<Proc>, FleetError> {
        let opts = self.opts;
        if self.plan.fleet.operator_heartbeat.is_none() {
            return Ok(None);
        }
        let mut args = vec![
            "fleet".to_owned(),
            "heartbeat".to_owned(),
            opts.scenario.clone(),
            "--time-scale".to_owned(),
            opts.time_scale.to_string(),
        ];
        args.extend(chaos_args(&opts.chaos, Member::Operator));
        args.extend(self.common(self.leader_at + 1, &Member::Operator.identity()));
        Ok(Some(self.spawn(Role::Operator.name(), &args, &[])?))
    }

    /// Starts hostile input on every key (`fleet garbage`), when asked.
    pub(super) fn spawn_garbage(&self) -> Result<Option<Proc>, FleetError> {
        let opts = self.opts;
        let Some((from, len)) = opts.chaos.garbage else {
            return Ok(None);
        };
        let mut args = vec![
            "fleet".to_owned(),
            "garbage".to_owned(),
            opts.scenario.clone(),
            "--from".to_owned(),
            from.to_string(),
            "--for".to_owned(),
            len.to_string(),
            "--time-scale".to_owned(),
            opts.time_scale.to_string(),
        ];
        // A peer of the operator's site, as anyone reaching the router.
        args.extend(self.common(self.leader_at + 1, &Member::Operator.identity()));
        Ok(Some(self.spawn("garbage", &args, &[])?))
    }

    /// Starts the robots on the hub, each from its robot file (the type an
    /// on-board robot's bundle holds, its operator token at `token_file`),
    /// one process each (`fleet robot --config`) or a few per process
    /// (`fleet host --config …`, [`hosts::per_process`]); the on-board ones
    /// join by themselves. Returns the processes, the agents on the hub and
    /// each process's agents.
    pub(super) fn spawn_robots(
        &self,
        token_file: &Path,
    ) -> Result<(Vec<Proc>, Vec<u32>, hosts::Groups), FleetError> {
        let (opts, n) = (self.opts, self.plan.n);
        let on_hub: Vec<u32> = (1..=n as u32)
            .filter(|&k| {
                self.plan.fleet.placement[k as usize - 1] == Placement::Hub || opts.hub.is_none()
            })
            .collect();
        let groups = hosts::group(&on_hub, self.plan.per_process, |k| {
            self.site_of(self.robot_at(k as usize))
        });
        let mut robots = Vec::with_capacity(groups.len());
        for group in &groups {
            // `fleet robot`, or `fleet host` of several.
            let command = match group.len() {
                1 => Role::Robot.name(),
                _ => "host",
            };
            let mut args = vec!["fleet".to_owned(), command.to_owned()];
            for &k in group {
                let i = self.robot_at(k as usize);
                let file = robots::write_robot_file(
                    opts,
                    &self.plan.scenario,
                    k,
                    n as u32,
                    self.plan.duration,
                    self.net.net_section(i, self.site_of(i)),
                    token_file,
                )?;
                args.extend(["--config".to_owned(), file.display().to_string()]);
            }
            robots.push(self.spawn(&hosts::role_of(group), &args, &[])?);
        }
        Ok((robots, on_hub, groups))
    }

    /// Hub mode: waits until every robot has joined (the reference starts
    /// then), `procs` watched meanwhile; on failure every one of them but
    /// `fleet garbage` is asked to stop.
    pub(super) fn wait_for_joins(
        &self,
        hub: &HubOptions,
        procs: &mut Procs,
        stop: &StopFlag,
    ) -> Result<(), FleetError> {
        let (opts, n, fleet) = (self.opts, self.plan.n, &self.plan.fleet);
        let awaited: join::Awaited = (1..=n as u32)
            .map(|k| (k, fleet.placement[k as usize - 1]))
            .collect();
        let session = crate::net::NetOptions {
            mode: Some(crate::net::Mode::Client),
            connect: vec![self.net.routers[0].clone()],
            secure: opts.secure.as_ref().map(|dir| crate::net::Secure {
                dir: dir.clone(),
                identity: Member::Leader.identity(),
                robots: n as u32,
                ros2: crate::net::ros_acl(&fleet.ros2),
            }),
            ..crate::net::NetOptions::default()
        };
        let keys = crate::keys::Keys::new(&fleet.name);
        let waited = join::wait_for_robots(
            &session,
            &keys,
            &awaited,
            Duration::from_secs_f64(hub.wait),
            stop,
            &mut || {
                poll_all(
                    std::iter::once(&mut procs.collector)
                        .chain(&mut procs.robots)
                        .chain(&mut procs.bases)
                        .chain(procs.operator.as_mut())
                        .chain(&mut procs.routers),
                )?;
                match std::iter::once(&procs.collector)
                    .chain(&procs.robots)
                    .chain(&procs.bases)
                    .chain(&procs.routers)
                    .find(|p| p.status.is_some())
                {
                    Some(p) => Err(FleetError::Child(
                        p.failure()
                            .unwrap_or_else(|| format!("{} stopped early", p.role)),
                    )),
                    None => Ok(()),
                }
            },
        );
        if let Err(e) = waited {
            for p in std::iter::once(&procs.collector)
                .chain(&procs.robots)
                .chain(&procs.bases)
                .chain(procs.operator.iter())
                .chain(&procs.routers)
            {
                p.terminate();
            }
            return Err(e);
        }
        Ok(())
    }

    /// Starts the leader, on the fleet's clock, waiting for the collector,
    /// the operator's heartbeat (`with_operator`), every robot and base;
    /// with the operator token in `token_env`.
    pub(super) fn spawn_leader(
        &self,
        with_operator: bool,
        token_env: &[(&str, &str)],
    ) -> Result<Proc, FleetError> {
        let mut args = self.on_clock(Role::Leader);
        args.extend(chaos_args(&self.opts.chaos, Member::Leader));
        args.extend(["--wait-for".to_owned(), Role::Collector.name().to_owned()]);
        if with_operator {
            args.extend(["--wait-for".to_owned(), Member::Operator.liveliness()]);
        }
        for k in 1..=self.plan.n {
            args.extend([
                "--wait-for".to_owned(),
                Member::Robot(k as u32).liveliness(),
            ]);
        }
        for k in 1..=self.plan.bases {
            args.extend(["--wait-for".to_owned(), Member::Base(k as u32).liveliness()]);
        }
        args.extend(self.common(self.leader_at, &Member::Leader.identity()));
        self.spawn(Role::Leader.name(), &args, token_env)
    }
}
