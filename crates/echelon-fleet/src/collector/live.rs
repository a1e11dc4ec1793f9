//! The live fleet in Foxglove (`fleet collector --foxglove ADDR`, `fleet up
//! --foxglove`): what the collector records, served as it arrives through
//! the `foxglove` crate's WebSocket server (Foxglove's WebSocket protocol,
//! subprotocol `foxglove.sdk.v1`): the same channels as `fleet.mcap` (the
//! JSON ones, the ROS 2 ones, and the 3D channels of [`echelon_mcap::scene`]).
//!
//! Backpressure: the collector hands each record to [`LiveFeed`] with a
//! non-blocking send into a bounded queue ([`QUEUE`] records); when the
//! queue is full the record is dropped and counted ([`LiveReport::dropped`]),
//! so a slow server thread never slows the collector. Message buffers go
//! back to the collector once served, so a warm feed does not allocate per
//! record. The server thread
//! feeds the `foxglove` crate's server, whose queue per viewer is bounded
//! too ([`BACKLOG`] messages, set explicitly; the oldest dropped when a
//! viewer does not read), so a stalled viewer never slows it either.
//!
//! What is counted, and what is not: the collector's queue's drops exactly
//! ([`LiveReport::dropped`]), and the messages the server thread gave the
//! crate to send ([`LiveReport::served`]; each goes into the queue of every
//! viewer subscribed to its channel). A viewer's own drops are **not**
//! counted: `foxglove` 0.25 drops a slow viewer's oldest messages inside
//! its server (`send_lossy`, whose result it discards) and exposes no
//! count, callback or queue depth for them (its only trace is a log line
//! at most every 30 s). What is known is the bound: a viewer holds at most
//! [`BACKLOG`] of them unread ([`LiveReport::viewer_backlog`]), so one that
//! subscribes to everything and never reads loses all but [`BACKLOG`] of
//! [`LiveReport::served`].

use std::collections::BTreeMap;
use std::net::SocketAddr;
use std::sync::Arc;
use std::sync::mpsc::{Receiver, RecvTimeoutError, SyncSender, TrySendError, sync_channel};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use echelon_mcap::scene::{SCENE_STATIC_TOPIC, SCENE_TOPIC, Scene, ScenePose, SceneSpec, TF_TOPIC};
use foxglove::messages::{FrameTransforms, SceneUpdate};
use foxglove::{Context, RawChannel, Schema, WebSocketServer};
use serde::{Deserialize, Serialize};

use super::sink::{Channel, RecordSink, Stamp};
use crate::FleetError;

/// Records the collector may have queued for the server thread.
pub const QUEUE: usize = 4096;
/// Messages the server queues per viewer before dropping its oldest.
pub const BACKLOG: usize = 1024;
/// How often the fixed scene is sent again, for viewers that joined late.
const FIXED_EVERY: Duration = Duration::from_secs(1);
/// Foxglove's default WebSocket address.
pub const DEFAULT_ADDR: &str = "127.0.0.1:8765";
/// The dashboard's default address.
pub const DEFAULT_DASHBOARD: &str = "127.0.0.1:8766";

/// What the live feed did (`collector.json`'s `live`).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LiveReport {
    /// The server's address, `ws://HOST:PORT`.
    pub address: String,
    /// Records handed to the server thread.
    pub queued: u64,
    /// Records dropped because its queue was full.
    pub dropped: u64,
    /// Most viewers connected at once.
    pub max_clients: u64,
    /// Messages the server thread gave the `foxglove` server to send (each
    /// to every viewer subscribed to its channel).
    #[serde(default)]
    pub served: u64,
    /// Messages the `foxglove` server queues per viewer, [`BACKLOG`]; a
    /// viewer's older unread ones are dropped, uncounted (the module doc).
    #[serde(default)]
    pub viewer_backlog: u64,
}

/// One record for the server thread.
enum Item {
    /// Channel `id`, before its first message.
    Channel {
        id: usize,
        topic: String,
        schema: Schema,
        message_encoding: String,
    },
    /// A message on channel `id` (already announced), received at UNIX ns;
    /// its buffer goes back to the collector once served.
    Message {
        id: usize,
        log_time: u64,
        data: Vec<u8>,
    },
    /// Robot `k` moved.
    Pose { k: u32, pose: ScenePose },
}

/// The collector's side of the live feed: a bounded, never blocking queue
/// to the server thread, which owns the WebSocket server.
pub struct LiveFeed {
    tx: Option<SyncSender<Item>>,
    /// Channel ids by topic, once announced.
    announced: BTreeMap<String, usize>,
    /// Message buffers the server thread gave back (at most [`QUEUE`] in
    /// use at once): no allocation per record once warm.
    free: Receiver<Vec<u8>>,
    report: LiveReport,
    thread: Option<JoinHandle<Result<Served, FleetError>>>,
}

impl std::fmt::Debug for LiveFeed {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("LiveFeed")
            .field("report", &self.report)
            .finish_non_exhaustive()
    }
}

impl LiveFeed {
    /// Starts the WebSocket server on `addr` (port 0: any free port) and its
    /// thread; with `scene`, the 3D channels too. Returns once it listens.
    pub fn start(addr: SocketAddr, scene: Option<&SceneSpec>) -> Result<LiveFeed, FleetError> {
        let (tx, rx) = sync_channel(QUEUE);
        let (ready_tx, ready_rx) = sync_channel(1);
        let (free_tx, free) = sync_channel(QUEUE);
        let scene = scene.map(Scene::new);
        let thread = std::thread::Builder::new()
            .name("foxglove".into())
            .spawn(move || serve(addr, scene, &rx, &ready_tx, &free_tx))
            .map_err(|e| FleetError::Config(format!("foxglove: no thread: {e}")))?;
        let bound = match ready_rx.recv() {
            Ok(bound) => bound,
            Err(_) => {
                return Err(match thread.join() {
                    Ok(Err(e)) => e,
                    _ => FleetError::Config("foxglove: the server thread ended".into()),
                });
            }
        };
        Ok(LiveFeed {
            tx: Some(tx),
            announced: BTreeMap::new(),
            free,
            report: LiveReport {
                address: format!("ws://{bound}"),
                viewer_backlog: BACKLOG as u64,
                ..LiveReport::default()
            },
            thread: Some(thread),
        })
    }

    /// The server's address, `ws://HOST:PORT`.
    pub fn address(&self) -> &str {
        &self.report.address
    }

    /// Hands `item` over if there is room; counts it either way.
    fn send(&mut self, item: Item) -> bool {
        let Some(tx) = &self.tx else { return false };
        match tx.try_send(item) {
            Ok(()) => {
                self.report.queued += 1;
                true
            }
            Err(TrySendError::Full(_) | TrySendError::Disconnected(_)) => {
                self.report.dropped += 1;
                false
            }
        }
    }

    fn message(
        &mut self,
        topic: &str,
        schema: impl FnOnce() -> (Schema, &'static str),
        log_time: u64,
        data: &[u8],
    ) {
        let id = match self.announced.get(topic) {
            Some(&id) => id,
            None => {
                let id = self.announced.len();
                let (schema, message_encoding) = schema();
                let item = Item::Channel {
                    id,
                    topic: topic.to_owned(),
                    schema,
                    message_encoding: message_encoding.to_owned(),
                };
                if !self.send(item) {
                    return;
                }
                self.announced.insert(topic.to_owned(), id);
                id
            }
        };
        let mut buf = self.free.try_recv().unwrap_or_default();
        buf.clear();
        buf.extend_from_slice(data);
        self.send(Item::Message {
            id,
            log_time,
            data: buf,
        });
    }

    /// Stops the server; what it did.
    pub fn finish(mut self) -> Result<LiveReport, FleetError> {
        self.tx = None;
        if let Some(thread) = self.thread.take() {
            let served = thread
                .join()
                .map_err(|_| FleetError::Config("foxglove: the server thread panicked".into()))??;
            self.report.max_clients = served.max_clients;
            self.report.served = served.messages;
        }
        Ok(self.report.clone())
    }
}

impl RecordSink for LiveFeed {
    fn log(&mut self, channel: Channel<'_>, stamp: Stamp, data: &[u8]) -> Result<(), FleetError> {
        let schema = || match channel {
            Channel::Json(_, schema) => (
                Schema::new(schema.name, "jsonschema", schema.schema.as_bytes().to_vec()),
                "json",
            ),
            Channel::Ros(topic) => {
                let s = topic.schema();
                (
                    Schema::new(
                        s.name,
                        echelon_mcap::ROS2MSG,
                        s.definition.as_bytes().to_vec(),
                    ),
                    echelon_mcap::CDR,
                )
            }
        };
        self.message(channel.topic(), schema, stamp.log_time, data);
        Ok(())
    }

    fn row(&mut self, _: &echelon::sample::AgentSample) -> Result<(), FleetError> {
        Ok(())
    }

    fn pose(&mut self, k: u32, pose: &ScenePose, _: Stamp) -> Result<(), FleetError> {
        self.send(Item::Pose { k, pose: *pose });
        Ok(())
    }
}

/// Every record to both sinks: the files, then the live feed.
pub(super) struct Tee<'a, A, B>(pub(super) &'a mut A, pub(super) &'a mut B);

impl<A: RecordSink, B: RecordSink> RecordSink for Tee<'_, A, B> {
    fn log(&mut self, channel: Channel<'_>, stamp: Stamp, data: &[u8]) -> Result<(), FleetError> {
        self.0.log(channel, stamp, data)?;
        self.1.log(channel, stamp, data)
    }

    fn row(&mut self, sample: &echelon::sample::AgentSample) -> Result<(), FleetError> {
        self.0.row(sample)?;
        self.1.row(sample)
    }

    fn odometry(
        &mut self,
        s: &crate::wire::RobotState,
        o: &crate::wire::OdometryState,
    ) -> Result<(), FleetError> {
        self.0.odometry(s, o)?;
        self.1.odometry(s, o)
    }

    fn pose(&mut self, k: u32, pose: &ScenePose, stamp: Stamp) -> Result<(), FleetError> {
        self.0.pose(k, pose, stamp)?;
        self.1.pose(k, pose, stamp)
    }
}

/// What the server thread did.
#[derive(Debug, Clone, Copy, Default)]
struct Served {
    /// Most viewers connected at once.
    max_clients: u64,
    /// Messages given to the `foxglove` server to send.
    messages: u64,
}

/// The server thread: the WebSocket server on `addr` (its bound address
/// sent on `ready`), fed from `rx` until the collector hangs up; what it
/// did.
fn serve(
    addr: SocketAddr,
    mut scene: Option<Scene>,
    rx: &Receiver<Item>,
    ready: &SyncSender<SocketAddr>,
    free: &SyncSender<Vec<u8>>,
) -> Result<Served, FleetError> {
    let failed = |e: &dyn std::fmt::Display| FleetError::Config(format!("foxglove {addr}: {e}"));
    // One worker: the server must not take the fleet's cores.
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(1)
        .thread_name("foxglove-ws")
        .enable_all()
        .build()
        .map_err(|e| failed(&e))?;
    let ctx = Context::new();
    let server = WebSocketServer::new()
        .name("echelon")
        .context(&ctx)
        .bind(addr.ip().to_string(), addr.port())
        .message_backlog_size(BACKLOG)
        .tokio_runtime(runtime.handle())
        .start_blocking()
        .map_err(|e| failed(&e))?;
    let bound = SocketAddr::new(addr.ip(), server.port());
    let _ = ready.send(bound);
    let mut channels: Vec<Option<Arc<RawChannel>>> = Vec::new();
    let tf: foxglove::Channel<FrameTransforms> = ctx.channel_builder(TF_TOPIC).build();
    let scene_channel: foxglove::Channel<SceneUpdate> = ctx.channel_builder(SCENE_TOPIC).build();
    let fixed_channel: foxglove::Channel<SceneUpdate> =
        ctx.channel_builder(SCENE_STATIC_TOPIC).build();
    let mut fixed_sent: Option<Instant> = None;
    let mut last_t = 0.0;
    let mut served = Served::default();
    loop {
        served.max_clients = served.max_clients.max(server.client_count() as u64);
        if let Some(scene) = scene.as_mut()
            && fixed_sent.is_none_or(|at| at.elapsed() >= FIXED_EVERY)
        {
            fixed_sent = Some(Instant::now());
            fixed_channel.log(scene.fixed(last_t));
            served.messages += 1;
        }
        let item = match rx.recv_timeout(FIXED_EVERY) {
            Ok(item) => item,
            Err(RecvTimeoutError::Timeout) => continue,
            Err(RecvTimeoutError::Disconnected) => break,
        };
        match item {
            Item::Channel {
                id,
                topic,
                schema,
                message_encoding,
            } => {
                let channel = ctx
                    .channel_builder(topic.as_str())
                    .message_encoding(message_encoding)
                    .schema(schema)
                    .build_raw()
                    .map_err(|e| failed(&e))?;
                if channels.len() <= id {
                    channels.resize(id + 1, None);
                }
                channels[id] = Some(channel);
            }
            Item::Message { id, log_time, data } => {
                if let Some(Some(channel)) = channels.get(id) {
                    channel.log_with_meta(
                        &data,
                        foxglove::PartialMetadata {
                            log_time: Some(log_time),
                        },
                    );
                    served.messages += 1;
                }
                // The buffer back to the collector (dropped if it has enough).
                let _ = free.try_send(data);
            }
            Item::Pose { k, pose } => {
                let Some(scene) = scene.as_mut() else {
                    continue;
                };
                last_t = pose.t;
                if scene.set(k, &pose).is_some()
                    && let Some((t, update)) = scene.robot(k)
                {
                    tf.log(t);
                    scene_channel.log(update);
                    served.messages += 2;
                }
            }
        }
    }
    server.stop().wait_blocking();
    drop(runtime);
    Ok(served)
}
