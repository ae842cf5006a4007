//! What the two peers share: the scene file bench/compare.py writes, the step loop that times
//! every step on this thread's CPU clock and the wall clock, and the JSON printed on stdout.
//! Z is up, SI units throughout.
use serde::{Deserialize, Serialize};
use std::time::Instant;

#[derive(Deserialize)]
pub struct Material {
    pub friction: f32,
    pub restitution: f32,
}

#[derive(Deserialize)]
pub struct Ground {
    /// m: the top face of the ground, a flat plane.
    pub height: f32,
    #[serde(flatten)]
    pub material: Material,
}

#[derive(Deserialize)]
pub struct SceneBox {
    pub half_extents: [f32; 3],
    pub position: [f32; 3],
    /// x, y, z, w
    pub quaternion: [f32; 4],
    /// kg
    pub mass: f32,
    #[serde(flatten)]
    pub material: Material,
}

impl SceneBox {
    /// kg/m^3: the engines take a density and derive mass and inertia from the shape.
    pub fn density(&self) -> f32 {
        let [x, y, z] = self.half_extents;
        self.mass / (8.0 * x * y * z)
    }
}

#[derive(Deserialize)]
pub struct Scene {
    /// s
    pub dt: f32,
    pub steps: usize,
    /// m/s^2
    pub gravity: [f32; 3],
    pub sleeping: bool,
    /// CPU seconds after which the run stops early (as compare.py's own engines do).
    pub budget_s: f64,
    /// Threads the engine may step on, the calling one included (1 unless the scene asks).
    #[serde(default = "one_thread")]
    pub threads: usize,
    pub ground: Ground,
    pub boxes: Vec<SceneBox>,
}

fn one_thread() -> usize {
    1
}

#[derive(Serialize)]
pub struct Report {
    pub engine: String,
    /// This thread's CPU milliseconds of each step run.
    pub cpu_ms: Vec<f64>,
    pub wall_ms: Vec<f64>,
    pub complete: bool,
    /// CPU seconds of the whole process over the steps: more than the thread's sum would mean
    /// the engine used other threads.
    pub process_cpu_s: f64,
    /// s of wall time to build the world (not in the step figures).
    pub setup_s: f64,
    pub positions: Vec<[f32; 3]>,
    pub asleep: usize,
    /// Anything the engine reported going wrong during the run.
    pub errors: Vec<String>,
}

fn cpu_seconds(clock: libc::clockid_t) -> f64 {
    let mut now = libc::timespec { tv_sec: 0, tv_nsec: 0 };
    // SAFETY: clock_gettime only writes the timespec it is given.
    unsafe { libc::clock_gettime(clock, &mut now) };
    now.tv_sec as f64 + now.tv_nsec as f64 * 1e-9
}

/// The scene file named by the first argument.
pub fn read_scene() -> Scene {
    let path = std::env::args().nth(1).expect("usage: <engine>_bench SCENE.json");
    let text = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("cannot read {path}: {e}"));
    serde_json::from_str(&text).unwrap_or_else(|e| panic!("{path} is not a scene: {e}"))
}

pub struct Timing {
    pub cpu_ms: Vec<f64>,
    pub wall_ms: Vec<f64>,
    pub complete: bool,
    pub process_cpu_s: f64,
}

/// Runs `step` scene.steps times, or until the steps have spent scene.budget_s CPU seconds.
pub fn timed_steps(scene: &Scene, mut step: impl FnMut()) -> Timing {
    let mut timing = Timing { cpu_ms: Vec::with_capacity(scene.steps), wall_ms: Vec::with_capacity(scene.steps),
                              complete: true, process_cpu_s: 0.0 };
    let process_start = cpu_seconds(libc::CLOCK_PROCESS_CPUTIME_ID);
    let mut spent_s = 0.0;
    for _ in 0..scene.steps {
        if spent_s > scene.budget_s {
            timing.complete = false;
            break;
        }
        let wall = Instant::now();
        let cpu = cpu_seconds(libc::CLOCK_THREAD_CPUTIME_ID);
        step();
        let cpu = cpu_seconds(libc::CLOCK_THREAD_CPUTIME_ID) - cpu;
        timing.wall_ms.push(wall.elapsed().as_secs_f64() * 1e3);
        timing.cpu_ms.push(cpu * 1e3);
        spent_s += cpu;
    }
    timing.process_cpu_s = cpu_seconds(libc::CLOCK_PROCESS_CPUTIME_ID) - process_start;
    timing
}

impl Report {
    pub fn new(engine: String, timing: Timing, setup_s: f64, positions: Vec<[f32; 3]>, asleep: usize,
               errors: Vec<String>) -> Self {
        Report { engine, cpu_ms: timing.cpu_ms, wall_ms: timing.wall_ms, complete: timing.complete,
                 process_cpu_s: timing.process_cpu_s, setup_s, positions, asleep, errors }
    }

    pub fn print(&self) {
        println!("{}", serde_json::to_string(self).expect("a report is always serialisable"));
    }
}
