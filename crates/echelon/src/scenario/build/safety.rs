//! The `[safety]` sections built into every agent's filter: impossible
//! settings refused, and a robot that starts within the radius of another
//! or of an obstacle.

use super::*;

impl Builder<'_> {
    /// The safety filter of every agent (`None`: no agent filters), refusing
    /// impossible settings and a robot that starts within `radius` of another
    /// or of an obstacle.
    pub(super) fn safety(&self, agents: &Agents) -> Result<Option<SafetySpec>, ScenarioError> {
        let f = self.file;
        let global = FieldPath::from("safety");
        let any = f.safety.is_some() || f.agents.iter().any(|a| a.safety.is_some());
        if !any {
            return Ok(None);
        }
        for (i, a) in f.agents.iter().enumerate() {
            let own = FieldPath::from("agents").index(i).key("safety");
            if a.safety.is_some() && f.safety.is_none() {
                return Err(self.at.error(
                    &own,
                    "an agent's safety settings refine the [safety] section, and there is none: add [safety] with radius = the smallest distance between two robots' points L ahead (m)",
                ));
            }
            if let Some(s) = &a.safety {
                if s.radius.is_some() {
                    return Err(self.at.error(
                        &own.key("radius"),
                        "the safety radius is a property of every pair of robots: set it in [safety]",
                    ));
                }
                if s.obstacles.is_some() {
                    return Err(self.at.error(
                        &own.key("obstacles"),
                        "obstacles are known to every robot: list them in [safety]",
                    ));
                }
            }
        }
        let g = f.safety.clone().unwrap_or_default();
        let radius = match g.radius {
            Some(r) => self.at(&global.key("radius"), check::positive("radius", r))?,
            None => {
                return Err(self.at.error(
                    &global,
                    "missing field `radius` (m): the smallest distance between two robots' points L ahead",
                ));
            }
        };
        let obstacles = g
            .obstacles
            .iter()
            .flatten()
            .enumerate()
            .map(|(k, o)| {
                self.within(
                    &global.key("obstacles").index(k),
                    Obstacle::new(o.x, o.y, o.r),
                )
            })
            .collect::<Result<Vec<_>, _>>()?;
        let mut configs = Vec::with_capacity(f.agents.len());
        for (i, a) in f.agents.iter().enumerate() {
            let m = Merge::new(
                a.safety.as_ref(),
                f.safety.as_ref(),
                FieldPath::from("agents").index(i).key("safety"),
                global.clone(),
            );
            if !m.get_or(|s| s.enabled, "enabled", true).0 {
                configs.push(None);
                continue;
            }
            let (gain, gain_at) = m.get_or(|s| s.gain, "gain", 1.0);
            self.at(&gain_at, check::positive("gain", gain))?;
            let (range, range_at) = m.get_or(|s| s.range, "range", f64::INFINITY);
            let config = self.at(&range_at, SafetyConfig::new(radius, gain, range))?;
            configs.push(Some(config));
        }
        let points: Vec<[f64; 2]> = agents
            .specs()
            .iter()
            .map(|a| crate::safety::point(&a.start(), a.placement().l()))
            .collect();
        if let Some((i, e)) = crate::safety::start_conflict(&points, &configs, &obstacles) {
            return Err(self
                .at
                .param(&FieldPath::from("agents").index(i).key("start"), &e));
        }
        Ok(Some(SafetySpec {
            agents: configs,
            obstacles,
        }))
    }
}
