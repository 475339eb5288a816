//! The render thread: owns the [`Session`] (cache, producers, renderer) and renders interactive frames of the latest
//! view the window asked for, so that the window's thread never waits for a frame or a brick.
//!
//! The window posts [`ViewRequest`]s (camera, transfer function, settings); only the newest counts (a request that
//! arrives while a frame renders replaces any older one still waiting). The thread renders GigaVoxels' interactive
//! frames ([`Mode::Interactive`]: one pass with what is resident, then a bounded number of requests served), posts
//! each as a [`ShownFrame`], and goes on until a frame is final (nothing missing, nothing fading in) or the loading
//! stalls; then it sleeps until the next request. A view at rest is refined as [`Refinement`] says: by converged
//! passes that any new request interrupts (the default), or by more blended interactive frames.

use std::ops::ControlFlow;
use std::sync::mpsc::{self, Receiver, Sender};
use std::sync::{Arc, Condvar, Mutex, PoisonError};
use std::thread::JoinHandle;

use voxstream_core::Producer;
use voxstream_engine::{FrameRenderer, FrameResult, Mode, Session};
use voxstream_render::{Camera, RenderSettings, TransferFunction};

use crate::histogram::{sample_histogram, SampledHistogram};

/// Frames in a row that serve no request and leave some pending before the thread stops refining (a budget too
/// small for the view, or bricks that fail); enough for fades under way to finish.
const STALLED_FRAMES: u32 = 3 + voxstream_core::DEFAULT_FADE_FRAMES;

/// How a view at rest is refined to its final image.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Refinement {
    /// One interactive frame (what is resident), then converged passes that trace again only the pixels still
    /// missing data, stopped between passes by any new request; the final image replaces the interactive one at
    /// once. Fastest to the final image (the time of `voxstream render`), one visible change.
    #[default]
    Converged,
    /// Interactive frames with level blending until one is final: detail fades in, never pops, but each frame
    /// re-traces every pixel, so the final image comes several times later.
    Blended,
}

/// What the window wants drawn.
#[derive(Clone, Debug, PartialEq)]
pub struct ViewRequest {
    /// Increases with every change; echoed in the frames drawn for it.
    pub revision: u64,
    /// The camera.
    pub camera: Camera,
    /// The transfer function.
    pub transfer_function: TransferFunction,
    /// The settings, with the image size of this request (smaller while the view moves).
    pub settings: RenderSettings,
    /// Whether the view rests (no input for a moment): frames may then serve more requests, up to
    /// [`REST_PRODUCTION_MS`] of production each.
    pub at_rest: bool,
    /// The pools' budget, bytes: a change moves the session's pools to it (`Session::set_pool_budget`: they fill
    /// again from the root); a budget the tree cannot fit is refused with a message and the old one kept.
    pub pool_budget_bytes: u64,
}

/// While the view rests, the requests served per frame double while a frame's production takes less than half of
/// this, and halve (down to the session's own number) when it takes more: detail arrives in fewer, longer frames,
/// and a new input still waits for at most about this long.
pub const REST_PRODUCTION_MS: f64 = 400.0;

/// The most requests a frame at rest serves.
const MAX_REST_REQUESTS: usize = 1 << 16;

/// A frame ready to show.
#[derive(Clone, Debug)]
pub struct ShownFrame {
    /// The request it was drawn for.
    pub revision: u64,
    /// The camera it was drawn from.
    pub camera: Camera,
    /// Width and height in pixels.
    pub size: [u32; 2],
    /// Pixels, RGB, 8 bits, row by row from the top.
    pub rgb: Vec<u8>,
    /// Per pixel: whether its ray missed data (coarser data stood in).
    pub missing: Vec<bool>,
    /// Nothing missing and nothing fading in: refining is over for this view.
    pub is_final: bool,
    /// Requests still pending after the frame.
    pub pending: usize,
    /// Bricks produced while serving the frame's requests.
    pub bricks_produced: u64,
    /// Wall time of the frame (render and production), milliseconds.
    pub frame_ms: f64,
    /// Pool bytes resident after the frame, and the pools' budget.
    pub resident_bytes: [u64; 2],
    /// Bricks that could not be produced, one line each.
    pub failures: Vec<String>,
}

/// What the render thread reports.
#[derive(Debug)]
pub enum WorkerEvent {
    /// A frame.
    Frame(Box<ShownFrame>),
    /// The value histogram of the source, sampled once after the first frame.
    Histogram(SampledHistogram),
    /// A request could not be rendered (the message is for the window; the thread goes on with the next request).
    Error(String),
}

#[derive(Default)]
struct Inbox {
    latest: Option<ViewRequest>,
    stop: bool,
}

struct Shared {
    inbox: Mutex<Inbox>,
    wake: Condvar,
}

/// The handle the window keeps: post requests, collect events; dropping it stops and joins the thread.
pub struct RenderWorker {
    shared: Arc<Shared>,
    events: Receiver<WorkerEvent>,
    thread: Option<JoinHandle<()>>,
}

impl RenderWorker {
    /// Starts the thread on `session`; `notify` is called after each event (the window's repaint request).
    pub fn start<P, R>(
        session: Session<P, R>,
        refinement: Refinement,
        notify: impl Fn() + Send + 'static,
    ) -> std::io::Result<RenderWorker>
    where
        P: Producer + 'static,
        R: FrameRenderer + Send + 'static,
    {
        let shared = Arc::new(Shared { inbox: Mutex::new(Inbox::default()), wake: Condvar::new() });
        let (sender, events) = mpsc::channel();
        let thread_shared = shared.clone();
        let thread = std::thread::Builder::new()
            .name("voxstream-render".into())
            .spawn(move || render_loop(session, refinement, &thread_shared, &sender, &notify))?;
        Ok(RenderWorker { shared, events, thread: Some(thread) })
    }

    /// Asks for `request` to be drawn (replacing any request not started yet).
    pub fn request(&self, request: ViewRequest) {
        let mut inbox = self.shared.inbox.lock().unwrap_or_else(PoisonError::into_inner);
        inbox.latest = Some(request);
        self.shared.wake.notify_one();
    }

    /// Events posted since the last call, oldest first.
    pub fn events(&self) -> Vec<WorkerEvent> {
        self.events.try_iter().collect()
    }

    /// Whether the thread has ended (it ends only when stopped, or if it panicked).
    pub fn has_ended(&self) -> bool {
        self.thread.as_ref().is_none_or(|t| t.is_finished())
    }
}

impl Drop for RenderWorker {
    fn drop(&mut self) {
        {
            let mut inbox = self.shared.inbox.lock().unwrap_or_else(PoisonError::into_inner);
            inbox.stop = true;
            self.shared.wake.notify_one();
        }
        if let Some(thread) = self.thread.take() {
            // The thread stops after the frame it is drawing; a panic there was already reported.
            let _ = thread.join();
        }
    }
}

fn render_loop<P: Producer, R: FrameRenderer>(
    mut session: Session<P, R>,
    refinement: Refinement,
    shared: &Shared,
    events: &Sender<WorkerEvent>,
    notify: &dyn Fn(),
) {
    let base_requests = session.limits().requests_per_frame;
    let mut current: Option<ViewRequest> = None;
    let mut refining = false;
    let mut stalled_frames = 0;
    let mut histogram_sent = false;
    // Whether the current request has had its first (interactive) frame.
    let mut shown_once = false;
    // A budget refused once is not tried again until the window asks for another.
    let mut refused_budget = None;
    loop {
        let next = {
            let mut inbox = shared.inbox.lock().unwrap_or_else(PoisonError::into_inner);
            while !inbox.stop && inbox.latest.is_none() && !refining {
                inbox = shared.wake.wait(inbox).unwrap_or_else(PoisonError::into_inner);
            }
            if inbox.stop {
                return;
            }
            inbox.latest.take()
        };
        if let Some(request) = next {
            let budget = request.pool_budget_bytes;
            if budget != session.residency().budget_bytes && refused_budget != Some(budget) {
                if let Err(error) = session.set_pool_budget(budget) {
                    refused_budget = Some(budget);
                    let mib = budget as f64 / (1 << 20) as f64;
                    let _ = events.send(WorkerEvent::Error(format!("a budget of {mib:.1} MiB: {error}")));
                    notify();
                }
            }
            if let Err(message) = apply(&mut session, current.as_ref(), &request) {
                // The session may hold part of the refused request (its transfer function): compare with nothing.
                current = None;
                let _ = events.send(WorkerEvent::Error(message));
                notify();
                refining = false;
                continue;
            }
            if !request.at_rest {
                session.set_requests_per_frame(base_requests);
            }
            current = Some(request);
            refining = true;
            stalled_frames = 0;
            shown_once = false;
        }
        let Some(request) = &current else { continue };
        if refinement == Refinement::Converged && request.at_rest && shown_once {
            let mut interrupted = false;
            let result = session.render_interruptible(&request.camera, Mode::Converged, &mut |_| {
                let inbox = shared.inbox.lock().unwrap_or_else(PoisonError::into_inner);
                interrupted = inbox.stop || inbox.latest.is_some();
                if interrupted {
                    ControlFlow::Break(())
                } else {
                    ControlFlow::Continue(())
                }
            });
            // An interrupted frame is dropped (some of its pixels were never traced); the next request follows.
            refining = false;
            match result {
                Ok(frame) if !interrupted => {
                    let residency = session.residency();
                    let shown = shown_frame(request, frame, [residency.bytes, residency.budget_bytes]);
                    let _ = events.send(WorkerEvent::Frame(Box::new(shown)));
                }
                Ok(_) => {}
                Err(error) => {
                    let _ = events.send(WorkerEvent::Error(format!("cannot render this view: {error}")));
                }
            }
            notify();
            continue;
        }
        shown_once = true;
        match session.render(&request.camera, Mode::Interactive) {
            Ok(frame) => {
                // Nothing served with requests pending: nothing more will arrive (fades may still finish within
                // the allowance).
                let stalled = frame.pending > 0 && frame.served == 0;
                if request.at_rest {
                    let limit = session.limits().requests_per_frame;
                    let production_ms = frame.elapsed_ms - frame.render_ms;
                    if frame.served as usize >= limit && production_ms < REST_PRODUCTION_MS / 2.0 {
                        session.set_requests_per_frame((limit * 2).min(MAX_REST_REQUESTS));
                    } else if production_ms > REST_PRODUCTION_MS {
                        session.set_requests_per_frame((limit / 2).max(base_requests));
                    }
                }
                stalled_frames = if stalled { stalled_frames + 1 } else { 0 };
                refining = !frame.is_final() && stalled_frames < STALLED_FRAMES;
                let residency = session.residency();
                let shown = shown_frame(request, frame, [residency.bytes, residency.budget_bytes]);
                let _ = events.send(WorkerEvent::Frame(Box::new(shown)));
            }
            Err(error) => {
                refining = false;
                let _ = events.send(WorkerEvent::Error(format!("cannot render this view: {error}")));
            }
        }
        notify();
        if !histogram_sent {
            histogram_sent = true;
            let histogram = sample_histogram(session.cache().producer(), session.value_range());
            let _ = events.send(WorkerEvent::Histogram(histogram));
            notify();
        }
    }
}

/// Brings the session to `request`'s transfer function and settings.
fn apply<P: Producer, R: FrameRenderer>(
    session: &mut Session<P, R>,
    current: Option<&ViewRequest>,
    request: &ViewRequest,
) -> Result<(), String> {
    if current.is_none_or(|c| c.transfer_function != request.transfer_function) {
        session.set_transfer_function(&request.transfer_function);
    }
    if session.settings() != &request.settings {
        session.set_settings(request.settings.clone()).map_err(|e| format!("invalid settings: {e}"))?;
    }
    request
        .camera
        .frame(request.settings.width, request.settings.height)
        .map_err(|e| format!("invalid camera: {e}"))?;
    Ok(())
}

fn shown_frame(request: &ViewRequest, frame: FrameResult, resident_bytes: [u64; 2]) -> ShownFrame {
    ShownFrame {
        revision: request.revision,
        camera: request.camera,
        size: [frame.image.width, frame.image.height],
        rgb: frame.image.to_rgb8(),
        is_final: frame.is_final(),
        pending: frame.pending,
        bricks_produced: frame.bricks_produced,
        frame_ms: frame.elapsed_ms,
        resident_bytes,
        failures: frame.failures.iter().map(|f| f.to_string()).collect(),
        missing: frame.missing,
    }
}
