//! Who follows whom: a forest rooted at the virtual leader (the reference).
//!
//! Each agent has exactly one leader: the reference or another agent (chained
//! formations, paper section 4.1: agent 3 follows agent 1). The graph must be
//! acyclic; agents are evaluated leaders-first so that a follower sees its
//! leader's state and acceleration at the same instant.

use crate::error::FormationError;

pub mod agent;
pub mod follow;

/// An agent's leader. Agents are indexed from 0 here; errors and files count from 1.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Leader {
    /// The virtual leader: the scenario's reference trajectory.
    Reference,
    /// Another agent, by 0-based index.
    Agent(usize),
}

/// A validated leader graph with an evaluation order.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Formation {
    leaders: Vec<Leader>,
    depth: Vec<usize>,
    order: Vec<usize>,
}

impl Formation {
    /// Validates `leaders[i]` (agent `i`'s leader): no agent follows itself, a
    /// missing agent, or (through others) itself.
    pub fn new(leaders: Vec<Leader>) -> Result<Formation, FormationError> {
        let n = leaders.len();
        for (i, l) in leaders.iter().enumerate() {
            if let Leader::Agent(j) = *l {
                if j == i {
                    return Err(FormationError::SelfLeader(i + 1));
                }
                if j >= n {
                    return Err(FormationError::Dangling {
                        agent: i + 1,
                        leader: j + 1,
                        count: n,
                    });
                }
            }
        }
        // Each agent has one leader, so following leaders from any agent either
        // reaches the reference or enters a cycle.
        const UNKNOWN: usize = usize::MAX;
        let mut depth = vec![UNKNOWN; n];
        let mut path = Vec::new();
        for start in 0..n {
            path.clear();
            let mut i = start;
            let base = loop {
                if depth[i] != UNKNOWN {
                    break depth[i];
                }
                if let Some(pos) = path.iter().position(|&p| p == i) {
                    let mut cycle: Vec<usize> = path[pos..].iter().map(|&a| a + 1).collect();
                    let min = cycle
                        .iter()
                        .enumerate()
                        .min_by_key(|(_, a)| **a)
                        .map_or(0, |(k, _)| k);
                    cycle.rotate_left(min);
                    return Err(FormationError::Cycle(cycle));
                }
                path.push(i);
                match leaders[i] {
                    Leader::Reference => break 0,
                    Leader::Agent(j) => i = j,
                }
            };
            // Unwind: the last agent on the path is nearest the reference.
            let mut d = base;
            for &a in path.iter().rev() {
                if depth[a] == UNKNOWN {
                    d += 1;
                    depth[a] = d;
                }
            }
        }
        let mut order: Vec<usize> = (0..n).collect();
        order.sort_by_key(|&i| (depth[i], i));
        Ok(Formation {
            leaders,
            depth,
            order,
        })
    }

    /// Number of agents.
    pub fn len(&self) -> usize {
        self.leaders.len()
    }

    /// Whether there are no agents.
    pub fn is_empty(&self) -> bool {
        self.leaders.is_empty()
    }

    /// Agent `i`'s leader.
    pub fn leader(&self, i: usize) -> Leader {
        self.leaders[i]
    }

    /// All leaders, by agent.
    pub fn leaders(&self) -> &[Leader] {
        &self.leaders
    }

    /// Agent `i`'s distance from the reference (1 for a direct follower).
    pub fn depth(&self, i: usize) -> usize {
        self.depth[i]
    }

    /// Evaluation order: every leader before its followers (by depth, then index).
    pub fn order(&self) -> &[usize] {
        &self.order
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use Leader::{Agent, Reference};

    #[test]
    fn paper_pentagon_orders_leaders_first() {
        // Agents 1, 2 follow the reference; 3 follows 1; 4 follows 2.
        let f = Formation::new(vec![Reference, Reference, Agent(0), Agent(1)]).unwrap();
        assert_eq!(f.order(), &[0, 1, 2, 3]);
        assert_eq!(f.depth(3), 2);
    }

    #[test]
    fn long_chain_in_reverse_index_order() {
        let f = Formation::new(vec![Agent(1), Agent(2), Agent(3), Reference]).unwrap();
        assert_eq!(f.order(), &[3, 2, 1, 0]);
        assert_eq!(f.depth(0), 4);
    }

    #[test]
    fn cycles_are_named() {
        let err = Formation::new(vec![Reference, Agent(2), Agent(3), Agent(1)]).unwrap_err();
        assert_eq!(err, FormationError::Cycle(vec![2, 3, 4]));
        assert_eq!(
            err.to_string(),
            "agents 2 → 3 → 4 → 2 form a cycle of leaders: none of them reaches the reference"
        );
    }

    #[test]
    fn dangling_and_self_leaders_are_refused() {
        assert_eq!(
            Formation::new(vec![Reference, Agent(5)]).unwrap_err(),
            FormationError::Dangling {
                agent: 2,
                leader: 6,
                count: 2
            }
        );
        assert_eq!(
            Formation::new(vec![Agent(0)]).unwrap_err(),
            FormationError::SelfLeader(1)
        );
    }
}
