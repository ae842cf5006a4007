//! Jolt (5.0.0, through joltc-sys's JoltC) on a bench scene: default PhysicsSettings and body
//! settings, one collision step per update, a thread-pool job system with the scene's `threads`
//! less one worker threads (the calling thread runs jobs too while it waits on them: with none,
//! everything runs on it), Jolt's default combine rules (friction: the geometric mean;
//! restitution: the larger).
//!
//! JoltC cannot set the gravity, and Jolt's default is 9.81 m/s^2 along -Y: the scene (Z up) is
//! turned into Jolt's frame by a rotation of -90 degrees about X, (x, y, z) -> (x, z, -y).
use joltc_sys::*;
use peer_scene::{read_scene, timed_steps, Report, Scene};
use std::ffi::{c_void, CStr};
use std::ptr::{null, null_mut};
use std::time::Instant;

const LAYER_STATIC: JPC_ObjectLayer = 0;
const LAYER_MOVING: JPC_ObjectLayer = 1;
const BROAD_PHASE_STATIC: JPC_BroadPhaseLayer = 0;
const BROAD_PHASE_MOVING: JPC_BroadPhaseLayer = 1;

/// Jolt's limits are fixed up front; these leave room for the largest scene (5,000 boxes).
const MAX_BODY_PAIRS: u32 = 65536;
const MAX_CONTACT_CONSTRAINTS: u32 = 65536;
/// Jolt's own figures for its thread pool (cMaxPhysicsJobs, cMaxPhysicsBarriers).
const MAX_JOBS: u32 = 2048;
const MAX_BARRIERS: u32 = 8;
/// bytes preallocated for an update's temporary data
const TEMP_ALLOCATOR_BYTES: u32 = 64 * 1024 * 1024;

const GROUND_HALF_SIDE: f32 = 500.0;
const GROUND_HALF_THICKNESS: f32 = 0.5;

unsafe extern "C" fn broad_phase_layer_count(_: *const c_void) -> u32 {
    2
}

unsafe extern "C" fn broad_phase_layer_of(_: *const c_void, layer: JPC_ObjectLayer) -> JPC_BroadPhaseLayer {
    if layer == LAYER_STATIC { BROAD_PHASE_STATIC } else { BROAD_PHASE_MOVING }
}

/// Static bodies never need testing against each other.
unsafe extern "C" fn object_collides_with_broad_phase(_: *const c_void, layer: JPC_ObjectLayer,
                                                      broad_phase: JPC_BroadPhaseLayer) -> bool {
    layer == LAYER_MOVING || broad_phase == BROAD_PHASE_MOVING
}

unsafe extern "C" fn objects_collide(_: *const c_void, a: JPC_ObjectLayer, b: JPC_ObjectLayer) -> bool {
    a == LAYER_MOVING || b == LAYER_MOVING
}

/// Jolt keeps a copy of z in a Vec3's fourth lane.
fn vec3(x: f32, y: f32, z: f32) -> JPC_Vec3 {
    JPC_Vec3 { x, y, z, _w: z }
}

fn jolt_vector([x, y, z]: [f32; 3]) -> JPC_Vec3 {
    vec3(x, z, -y)
}

fn scene_vector(v: JPC_Vec3) -> [f32; 3] {
    [v.x, -v.z, v.y]
}

/// The scene's orientation (x, y, z, w) seen from Jolt's frame: the frame's rotation times it.
fn jolt_rotation([x, y, z, w]: [f32; 4]) -> JPC_Quat {
    let half = std::f32::consts::FRAC_1_SQRT_2; // -90 degrees about X: (-sin 45, 0, 0, cos 45)
    let (fx, fw) = (-half, half);
    let q = JPC_Quat { x: fw * x + fx * w, y: fw * y - fx * z, z: fw * z + fx * y, w: fw * w - fx * x };
    let norm = (q.x * q.x + q.y * q.y + q.z * q.z + q.w * q.w).sqrt();
    JPC_Quat { x: q.x / norm, y: q.y / norm, z: q.z / norm, w: q.w / norm }
}

/// A box shape of Jolt's default convex radius. Its half extents are in the body's own frame,
/// which the body's rotation (frame rotation included) carries into Jolt's.
unsafe fn box_shape(half_extents: [f32; 3], density: f32) -> *mut JPC_Shape {
    let [x, y, z] = half_extents;
    let mut settings = JPC_BoxShapeSettings::default();
    settings.HalfExtent = vec3(x, y, z);
    settings.Density = density;
    let (mut shape, mut error) = (null_mut(), null_mut());
    if !JPC_BoxShapeSettings_Create(&settings, &mut shape, &mut error) {
        panic!("Jolt refused a box {half_extents:?}: {}", CStr::from_ptr(JPC_String_c_str(error)).to_string_lossy());
    }
    shape
}

unsafe fn add_body(bodies: *mut JPC_BodyInterface, shape: *mut JPC_Shape, position: [f32; 3], rotation: [f32; 4],
                   moving: bool, friction: f32, restitution: f32, sleeping: bool) -> JPC_BodyID {
    let mut settings = JPC_BodyCreationSettings::default();
    settings.Position = jolt_vector(position);
    settings.Rotation = jolt_rotation(rotation);
    settings.MotionType = if moving { JPC_MOTION_TYPE_DYNAMIC } else { JPC_MOTION_TYPE_STATIC };
    settings.ObjectLayer = if moving { LAYER_MOVING } else { LAYER_STATIC };
    settings.Friction = friction;
    settings.Restitution = restitution;
    settings.AllowSleeping = sleeping;
    settings.Shape = shape;
    let activation = if moving { JPC_ACTIVATION_ACTIVATE } else { JPC_ACTIVATION_DONT_ACTIVATE };
    JPC_BodyInterface_CreateAndAddBody(bodies, &settings, activation)
}

fn main() {
    let scene: Scene = read_scene();
    // SAFETY: JoltC's objects are created here and used on this thread only; the process ends
    // right after the report, so nothing is freed.
    unsafe {
        let built = Instant::now();
        JPC_RegisterDefaultAllocator();
        JPC_FactoryInit();
        JPC_RegisterTypes();
        let temp_allocator = JPC_TempAllocatorImpl_new(TEMP_ALLOCATOR_BYTES);
        let job_system = JPC_JobSystemThreadPool_new3(MAX_JOBS, MAX_BARRIERS, scene.threads as i32 - 1);
        let layers = JPC_BroadPhaseLayerInterface_new(null(), JPC_BroadPhaseLayerInterfaceFns {
            GetNumBroadPhaseLayers: Some(broad_phase_layer_count),
            GetBroadPhaseLayer: Some(broad_phase_layer_of),
        });
        let object_vs_broad_phase = JPC_ObjectVsBroadPhaseLayerFilter_new(null(), JPC_ObjectVsBroadPhaseLayerFilterFns {
            ShouldCollide: Some(object_collides_with_broad_phase),
        });
        let object_pairs = JPC_ObjectLayerPairFilter_new(null(), JPC_ObjectLayerPairFilterFns {
            ShouldCollide: Some(objects_collide),
        });
        let system = JPC_PhysicsSystem_new();
        let max_bodies = scene.boxes.len() as u32 + 1;
        JPC_PhysicsSystem_Init(system, max_bodies, 0, MAX_BODY_PAIRS, MAX_CONTACT_CONSTRAINTS, layers,
                               object_vs_broad_phase, object_pairs);
        let bodies = JPC_PhysicsSystem_GetBodyInterface(system);

        let ground = &scene.ground;
        add_body(bodies, box_shape([GROUND_HALF_SIDE, GROUND_HALF_SIDE, GROUND_HALF_THICKNESS], 1.0),
                 [0.0, 0.0, ground.height - GROUND_HALF_THICKNESS], [0.0, 0.0, 0.0, 1.0], false,
                 ground.material.friction, ground.material.restitution, false);
        let ids: Vec<JPC_BodyID> = scene.boxes.iter().map(|b| {
            add_body(bodies, box_shape(b.half_extents, b.density()), b.position, b.quaternion, true,
                     b.material.friction, b.material.restitution, scene.sleeping)
        }).collect();
        // Jolt asks for this after adding many bodies at once (else its broad phase is unbalanced).
        JPC_PhysicsSystem_OptimizeBroadPhase(system);
        let setup_s = built.elapsed().as_secs_f64();

        let mut failed_updates = 0;
        let mut error_flags = 0;
        let timing = timed_steps(&scene, || {
            let error = JPC_PhysicsSystem_Update(system, scene.dt, 1, temp_allocator, job_system);
            if error != 0 {
                failed_updates += 1;
                error_flags |= error;
            }
        });
        let errors = if failed_updates > 0 {
            vec![format!("{failed_updates} updates overflowed Jolt's limits (JPC_PhysicsUpdateError flags {error_flags:#x})")]
        } else {
            Vec::new()
        };

        let positions = ids.iter().map(|&id| scene_vector(JPC_BodyInterface_GetPosition(bodies, id))).collect();
        let asleep = ids.iter().filter(|&&id| !JPC_BodyInterface_IsActive(bodies, id)).count();
        Report::new(format!("jolt 5.0.0 (joltc-sys 0.3.1), threads: {}", scene.threads), timing, setup_s, positions, asleep, errors).print();
    }
}
