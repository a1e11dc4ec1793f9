//! The Zenoh side of [`Outputs`]: a task's declared publishers, and its
//! session for what it puts without one.

use crate::FleetError;
use crate::net;

use super::{Outgoing, Outputs, declared};

/// A task's outputs on Zenoh. It owns what it publishes with (a session
/// handle and the publishers), so that it can go with the task to the
/// thread that ticks it.
pub(super) struct ZenohOutputs {
    pub(super) session: zenoh::Session,
    pub(super) publishers: Vec<zenoh::pubsub::Publisher<'static>>,
}

impl Outputs for ZenohOutputs {
    fn send(&mut self, m: Outgoing<'_>) -> Result<(), FleetError> {
        let publisher = declared(&self.publishers, m.output)?;
        net::send(&self.session, publisher, m.payload, m.attachment)
    }

    fn put(&mut self, key: &str, payload: &[u8]) {
        net::put_stamped(&self.session, key, payload.to_vec());
    }
}
