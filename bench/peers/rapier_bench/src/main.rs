//! Rapier on a bench scene: IntegrationParameters::default() with the scene's time step, the
//! default features (no "parallel": one thread), Rapier's default friction and restitution
//! combine rules (the average of the two colliders'). Built as rapier_parallel_bench too, with
//! Rapier's "parallel" feature: it then steps on the scene's `threads` (a rayon pool of that many).
use peer_scene::{read_scene, timed_steps, Report};
use rapier3d::prelude::*;
use std::time::Instant;

/// m: half the side of the ground slab, far wider than any scene.
const GROUND_HALF_SIDE: f32 = 500.0;
const GROUND_HALF_THICKNESS: f32 = 0.5;

fn main() {
    let scene = read_scene();
    #[cfg(feature = "parallel")]
    rapier3d::rayon::ThreadPoolBuilder::new().num_threads(scene.threads).build_global()
        .expect("the rayon pool is built once, before anything uses it");
    #[cfg(not(feature = "parallel"))]
    assert!(scene.threads == 1, "rapier_bench steps on one thread (rapier_parallel_bench takes `threads`)");
    let built = Instant::now();
    let mut world = PhysicsWorld::new();
    world.gravity = Vector::from(scene.gravity);
    world.integration_parameters.dt = scene.dt;

    let ground = world.insert_body(
        RigidBodyBuilder::fixed().translation(Vector::new(0.0, 0.0, scene.ground.height - GROUND_HALF_THICKNESS)));
    world.insert_collider(
        ColliderBuilder::cuboid(GROUND_HALF_SIDE, GROUND_HALF_SIDE, GROUND_HALF_THICKNESS)
            .friction(scene.ground.material.friction)
            .restitution(scene.ground.material.restitution),
        Some(ground));

    let handles: Vec<RigidBodyHandle> = scene.boxes.iter().map(|b| {
        let [x, y, z, w] = b.quaternion;
        let pose = Pose::from_parts(Vector::from(b.position), Rotation::from_xyzw(x, y, z, w).normalize());
        let [hx, hy, hz] = b.half_extents;
        world.insert(RigidBodyBuilder::dynamic().pose(pose).can_sleep(scene.sleeping),
                     ColliderBuilder::cuboid(hx, hy, hz).density(b.density())
                         .friction(b.material.friction).restitution(b.material.restitution)).0
    }).collect();
    let setup_s = built.elapsed().as_secs_f64();

    let timing = timed_steps(&scene, || world.step());

    let positions = handles.iter().map(|&h| world.bodies[h].translation().into()).collect();
    let asleep = handles.iter().filter(|&&h| world.bodies[h].is_sleeping()).count();
    let threads = if cfg!(feature = "parallel") { format!(", parallel, threads: {}", scene.threads) } else { String::new() };
    Report::new(format!("rapier3d {}{threads}", rapier3d::VERSION), timing, setup_s, positions, asleep, Vec::new()).print();
}
