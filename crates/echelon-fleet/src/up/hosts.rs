//! How many robots each of `fleet up`'s robot processes runs
//! (`--robots-per-process`, [`crate::host`]): one each for a small fleet,
//! real or ROS 2 robots, the secure mode (each robot's certificate is its
//! own) and a mesh (each process its own port); else enough per process
//! that the fleet's robots share a few processes per core.

use crate::FleetError;
use crate::role::Member;

use super::{Topology, UpOptions};

/// Each robot process's agents, in agent order.
pub(super) type Groups = Vec<Vec<u32>>;

/// Up to this many robots, one process each by default.
pub const ONE_EACH_UP_TO: usize = 16;
/// By default, about this many robot processes per core beyond
/// [`ONE_EACH_UP_TO`] robots.
pub const PROCESSES_PER_CORE: usize = 4;

/// Why robots of `opts` cannot share a process (`None`: they can).
fn why_one_each(opts: &UpOptions) -> Option<&'static str> {
    if opts.ros2 {
        Some("robots on ROS 2 bases keep a process each")
    } else if opts.secure.is_some() {
        Some("in the secure mode each robot's certificate names it alone")
    } else if opts.topology == Topology::Mesh {
        Some("in a mesh each process listens on a port of its own")
    } else if opts
        .chaos
        .kills
        .iter()
        .any(|(m, _)| matches!(m, Member::Robot(_)))
    {
        Some("a robot's rehearsed kill -9 (--die-at) would kill its host's other robots")
    } else if !opts.chaos.wall_clock_jumps.is_empty() {
        Some("a robot's wall-clock step is its process's, so its host's other robots'")
    } else {
        None
    }
}

/// The robots per process for `n` robots as `opts` asks (given: checked
/// against what must keep a process each), else chosen from `n` and the
/// machine's cores.
pub(super) fn per_process(opts: &UpOptions, n: usize) -> Result<usize, FleetError> {
    let why = why_one_each(opts);
    match (opts.robots_per_process, why) {
        (Some(0), _) => Err(FleetError::Config(
            "--robots-per-process 0: a process runs at least one robot".into(),
        )),
        (Some(k), Some(why)) if k > 1 => Err(FleetError::Config(format!(
            "--robots-per-process {k}: {why}; give 1"
        ))),
        (Some(k), _) => Ok(k),
        (None, Some(_)) => Ok(1),
        (None, None) if n <= ONE_EACH_UP_TO => Ok(1),
        (None, None) => {
            let cores = std::thread::available_parallelism().map_or(1, |c| c.get());
            Ok(n.div_ceil(PROCESSES_PER_CORE * cores).max(1))
        }
    }
}

/// `agents` grouped into processes of at most `k`, each group of one site
/// (`site` of an agent), in agent order.
pub(super) fn group(agents: &[u32], k: usize, site: impl Fn(u32) -> usize) -> Groups {
    let mut groups: Vec<(usize, Vec<u32>)> = Vec::new();
    for &a in agents {
        let s = site(a);
        match groups
            .iter_mut()
            .rev()
            .find(|(gs, g)| *gs == s && g.len() < k)
        {
            Some((_, g)) => g.push(a),
            None => groups.push((s, vec![a])),
        }
    }
    groups.into_iter().map(|(_, g)| g).collect()
}

/// The role (logs, reports, errors) of the process of `agents`:
/// `robot/K` alone, `robots/K-L` (or `robots/K,L,…`) hosted.
pub(super) fn role_of(agents: &[u32]) -> String {
    match agents {
        [k] => Member::Robot(*k).liveliness(),
        _ if agents.windows(2).all(|w| w[1] == w[0] + 1) => {
            format!("robots/{}-{}", agents[0], agents[agents.len() - 1])
        }
        _ => {
            let list: Vec<String> = agents.iter().map(u32::to_string).collect();
            format!("robots/{}", list.join(","))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        /// Every agent in exactly one group, in order, none bigger than `k`,
        /// each of one site.
        #[test]
        fn groups_cover_the_agents_once(
            n in 1usize..300, k in 1usize..60, sites in 1usize..4,
        ) {
            let agents: Vec<u32> = (1..=n as u32).collect();
            let site = |a: u32| a as usize % sites;
            let groups = group(&agents, k, site);
            let mut all: Vec<u32> = groups.iter().flatten().copied().collect();
            all.sort_unstable();
            prop_assert_eq!(&all, &agents);
            for g in &groups {
                prop_assert!(!g.is_empty() && g.len() <= k);
                prop_assert!(g.iter().all(|&a| site(a) == site(g[0])));
                prop_assert!(g.windows(2).all(|w| w[0] < w[1]));
            }
            if sites == 1 {
                prop_assert_eq!(groups.len(), n.div_ceil(k));
            }
        }
    }

    #[test]
    fn roles_name_the_agents() {
        assert_eq!(role_of(&[3]), "robot/3");
        assert_eq!(role_of(&[1, 2, 3]), "robots/1-3");
        assert_eq!(role_of(&[1, 3, 5]), "robots/1,3,5");
    }
}
