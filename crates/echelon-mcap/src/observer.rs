//! [`McapObserver`]: a simulation's frames into an MCAP log.

use std::io::{Seek, Write};

use echelon::reference::Reference;
use echelon::sample::AgentSample;
use echelon::sim::{Frame, Observer, ObserverError, Simulation};

use super::scene::{Scene, SceneChannels, ScenePose, SceneSpec};
use super::{
    AGENT_STATE, AgentStateRecord, McapLog, McapLogError, REFERENCE, REFERENCE_TOPIC,
    ReferenceRecord, agent_topic, nanos,
};

/// An [`Observer`] writing a simulation to MCAP (`echelon run --mcap`): the
/// reference and every agent, and the 3D channels ([`crate::scene`]: the
/// fixed scene once at the start, each robot's transform and scene), at
/// each frame it is shown (attach it with
/// [`Every`](echelon::sim::Every)`(log_every, …)` to log like `trajectory.csv`).
/// Its channels are registered when the run starts; the file's summary and
/// footer are written when the run finishes ([`McapObserver::into_inner`]
/// then returns the sink).
pub struct McapObserver<W: Write + Seek> {
    log: Option<McapLog<W>>,
    done: Option<W>,
    reference: Option<Reference>,
    reference_channel: u16,
    agent_channels: Vec<u16>,
    sequence: u32,
    scene: Option<(Scene, SceneChannels)>,
    /// Each robot's position at the frame being written.
    positions: Vec<[f64; 2]>,
}

impl<W: Write + Seek> std::fmt::Debug for McapObserver<W> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("McapObserver")
            .field("log", &self.log)
            .field("agents", &self.agent_channels.len())
            .finish_non_exhaustive()
    }
}

impl<W: Write + Seek> McapObserver<W> {
    /// Starts an MCAP stream on `w`.
    pub fn new(w: W) -> Result<Self, McapLogError> {
        Ok(McapObserver {
            log: Some(McapLog::new(w)?),
            done: None,
            reference: None,
            reference_channel: 0,
            agent_channels: Vec::new(),
            sequence: 0,
            scene: None,
            positions: Vec::new(),
        })
    }

    /// The sink of a finished file (`None` until the run has finished).
    pub fn into_inner(self) -> Option<W> {
        self.done
    }

    /// Messages written so far.
    pub fn messages(&self) -> u64 {
        self.log.as_ref().map_or(0, McapLog::messages)
    }

    fn log(&mut self) -> Result<&mut McapLog<W>, ObserverError> {
        self.log
            .as_mut()
            .ok_or_else(|| "MCAP: the file was already finished".into())
    }
}

impl<W: Write + Seek> Observer for McapObserver<W> {
    fn start(&mut self, sim: &Simulation) -> Result<(), ObserverError> {
        let log = self.log()?;
        let reference_channel = log.channel(REFERENCE_TOPIC, &REFERENCE)?;
        let agent_channels = (1..=sim.agents().len())
            .map(|k| log.channel(&agent_topic(k), &AGENT_STATE))
            .collect::<Result<Vec<_>, _>>()?;
        let channels = SceneChannels::register(log)?;
        self.reference_channel = reference_channel;
        self.agent_channels = agent_channels;
        self.reference = Some(sim.reference().clone());
        self.positions = vec![[0.0; 2]; sim.agents().len()];
        let scene = Scene::new(&SceneSpec::of(sim.plan()));
        self.scene = Some((scene, channels));
        Ok(())
    }

    fn observe(&mut self, frame: &Frame<'_>) -> Result<(), ObserverError> {
        let time = nanos(frame.t);
        let seq = self.sequence;
        self.sequence = self.sequence.wrapping_add(1);
        let reference = self
            .reference
            .as_ref()
            .ok_or("MCAP: shown a frame before the run started")?;
        let record = ReferenceRecord::at(reference, frame.t);
        let reference_channel = self.reference_channel;
        let log = self
            .log
            .as_mut()
            .ok_or("MCAP: the file was already finished")?;
        log.write_json(reference_channel, seq, time, time, &record)?;
        for (sample, &channel) in AgentSample::all(frame).zip(&self.agent_channels) {
            log.write_json(channel, seq, time, time, &AgentStateRecord::new(sample))?;
        }
        let Some((scene, channels)) = self.scene.as_mut() else {
            return Err("MCAP: shown a frame before the run started".into());
        };
        if seq == 0 {
            channels.fixed(log, scene, frame.t, time)?;
        }
        for (p, s) in self.positions.iter_mut().zip(frame.states) {
            *p = [s.x, s.y];
        }
        let p_d = record.motion;
        for (i, sample) in AgentSample::all(frame).enumerate() {
            let leader = scene.leader_point(i, &self.positions, [p_d.x, p_d.y]);
            let k = sample.agent;
            scene
                .set(k, &ScenePose::of(&sample, leader))
                .ok_or("MCAP: an agent the scene does not have")?;
            channels.robot(log, scene, k, time, time)?;
        }
        Ok(())
    }

    fn finish(&mut self) -> Result<(), ObserverError> {
        if let Some(log) = self.log.take() {
            self.done = Some(log.finish()?);
        }
        Ok(())
    }
}
