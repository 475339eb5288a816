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

/// While the view moves, a frame's production (serving requests) should take at most about this: the requests
/// served per moving frame halve after a frame whose production took longer, down to [`MIN_MOVING_REQUESTS`], and
/// double back (up to the session's own number) after frames that served all they could in under a quarter of it.
/// Production is counted in requests, so this bounds the next frames, not the one that overran.
pub const MOVING_PRODUCTION_MS: f64 = 20.0;

/// The fewest requests a moving frame serves (detail still arrives while the view moves).
const MIN_MOVING_REQUESTS: usize = 8;

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
    /// A pool budget the window asked for was refused (too small for the source) or failed on the renderer (e.g.
    /// GPU pools the adapter cannot hold); the session keeps (or went back to) `kept` bytes.
    BudgetRefused {
        /// Why, for the window.
        message: String,
        /// The budget in use, bytes.
        kept: u64,
    },
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
    // Requests per moving frame, adapted to MOVING_PRODUCTION_MS and kept from one moving request to the next.
    let mut moving_requests = base_requests;
    let mut current: Option<ViewRequest> = None;
    let mut refining = false;
    let mut stalled_frames = 0;
    let mut histogram_sent = false;
    // Whether the current request has had its first (interactive) frame.
    let mut shown_once = false;
    // The budget before the last change, until a frame has rendered at the new one (a renderer that cannot use it,
    // e.g. GPU pools larger than the adapter holds, fails that frame and the old budget comes back).
    let mut budget_before: Option<u64> = None;
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
            let in_use = session.residency().budget_bytes;
            if budget != in_use {
                match session.set_pool_budget(budget) {
                    Ok(()) => budget_before = Some(in_use),
                    Err(error) => {
                        let message = format!("a budget of {}: {error}", mib(budget));
                        let _ = events.send(WorkerEvent::BudgetRefused { message, kept: in_use });
                        notify();
                    }
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
                session.set_requests_per_frame(moving_requests);
            } else if current.as_ref().is_some_and(|c| !c.at_rest) {
                // From moving to rest: the rest frames' own adaptation starts from the session's number.
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
                    budget_before = None;
                    let residency = session.residency();
                    let shown = shown_frame(request, frame, [residency.bytes, residency.budget_bytes]);
                    let _ = events.send(WorkerEvent::Frame(Box::new(shown)));
                }
                Ok(_) => {}
                Err(error) => report_failure(&mut session, &mut budget_before, error, events),
            }
            notify();
            continue;
        }
        shown_once = true;
        match session.render(&request.camera, Mode::Interactive) {
            Ok(frame) => {
                budget_before = None;
                // Nothing served with requests pending: nothing more will arrive (fades may still finish within
                // the allowance).
                let stalled = frame.pending > 0 && frame.served == 0;
                let production_ms = frame.elapsed_ms - frame.render_ms;
                if !request.at_rest {
                    if production_ms > MOVING_PRODUCTION_MS {
                        moving_requests = (moving_requests / 2).max(MIN_MOVING_REQUESTS.min(base_requests));
                    } else if frame.served as usize >= moving_requests && production_ms < MOVING_PRODUCTION_MS / 4.0 {
                        moving_requests = (moving_requests * 2).min(base_requests);
                    }
                    session.set_requests_per_frame(moving_requests);
                }
                if request.at_rest {
                    let limit = session.limits().requests_per_frame;
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
                report_failure(&mut session, &mut budget_before, error, events);
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

/// Reports a frame that could not be rendered; if it was the first since a budget change, the renderer could not
/// use that budget (GPU pools the adapter cannot hold, out of memory): the budget before it comes back, and the
/// window is told which budget is in use.
fn report_failure<P: Producer, R: FrameRenderer>(
    session: &mut Session<P, R>,
    budget_before: &mut Option<u64>,
    error: voxstream_engine::EngineError,
    events: &Sender<WorkerEvent>,
) {
    let tried = session.residency().budget_bytes;
    match budget_before.take() {
        Some(kept) if session.set_pool_budget(kept).is_ok() => {
            let message = format!("a budget of {}: {error}; back to {}", mib(tried), mib(kept));
            let _ = events.send(WorkerEvent::BudgetRefused { message, kept });
        }
        _ => {
            let _ = events.send(WorkerEvent::Error(format!("cannot render this view: {error}")));
        }
    }
}

/// Bytes as MiB, for messages.
fn mib(bytes: u64) -> String {
    format!("{:.1} MiB", bytes as f64 / (1 << 20) as f64)
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

#[cfg(test)]
mod tests {
    use std::time::{Duration, Instant};

    use voxstream_engine::LoopLimits;
    use voxstream_procedural::Shell;

    use super::*;

    const BUDGET: u64 = 16 << 20;

    fn request(revision: u64, pool_budget_bytes: u64) -> ViewRequest {
        ViewRequest {
            revision,
            camera: Camera { eye: [0.5, 0.5, 3.0], target: [0.5, 0.5, 0.5], up: [0.0, 1.0, 0.0], fov: 30.0 },
            transfer_function: TransferFunction::new(vec![[0.0, 1.0, 1.0, 1.0, 0.0], [1.0, 1.0, 0.5, 0.2, 0.9]], None)
                .unwrap(),
            settings: RenderSettings { width: 24, height: 24, ..RenderSettings::default() },
            at_rest: true,
            pool_budget_bytes,
        }
    }

    /// Events until `done` says so (or a minute passes).
    fn events_until(worker: &RenderWorker, done: impl Fn(&[WorkerEvent]) -> bool) -> Vec<WorkerEvent> {
        let start = Instant::now();
        let mut events = Vec::new();
        while !done(&events) {
            assert!(start.elapsed() < Duration::from_secs(60), "no such event: {events:?}");
            events.extend(worker.events());
            std::thread::sleep(Duration::from_millis(5));
        }
        events
    }

    fn final_frame_of(revision: u64) -> impl Fn(&[WorkerEvent]) -> bool {
        move |events| events.iter().any(|e| matches!(e, WorkerEvent::Frame(f) if f.revision == revision && f.is_final))
    }

    #[test]
    fn a_new_budget_is_used_and_one_too_small_is_refused_keeping_the_old() {
        let request_one = request(1, BUDGET);
        let (tf, settings) = (request_one.transfer_function.clone(), request_one.settings.clone());
        let session = Session::new(Shell::default(), &tf, settings, BUDGET, LoopLimits::default()).unwrap();
        let worker = RenderWorker::start(session, Refinement::Converged, || {}).unwrap();
        worker.request(request_one);
        events_until(&worker, final_frame_of(1));

        // A smaller budget that fits: the frames say so.
        worker.request(request(2, BUDGET / 4));
        let events = events_until(&worker, final_frame_of(2));
        let budgets: Vec<u64> = events
            .iter()
            .filter_map(|e| match e {
                WorkerEvent::Frame(f) => Some(f.resident_bytes[1]),
                _ => None,
            })
            .collect();
        assert!(budgets.iter().all(|&b| b == BUDGET / 4), "{budgets:?}");

        // One byte: refused, the window told which budget is kept, and frames go on within it.
        worker.request(request(3, 1));
        let events = events_until(&worker, final_frame_of(3));
        let refusals: Vec<(&String, u64)> = events
            .iter()
            .filter_map(|e| match e {
                WorkerEvent::BudgetRefused { message, kept } => Some((message, *kept)),
                _ => None,
            })
            .collect();
        assert_eq!(refusals.len(), 1, "{events:?}");
        assert_eq!(refusals[0].1, BUDGET / 4);
        assert!(refusals[0].0.contains("a budget of 0.0 MiB"), "{}", refusals[0].0);
        let last = events.iter().rev().find_map(|e| match e {
            WorkerEvent::Frame(f) => Some(f.resident_bytes[1]),
            _ => None,
        });
        assert_eq!(last, Some(BUDGET / 4));
    }
}
