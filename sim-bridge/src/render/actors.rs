//! The moving part of a camera scene, rebuilt every frame: vehicles and parked cars as shaded
//! boxes (body, cabin, wheels), walkers, cyclists, and the lamps of every traffic light in the
//! state the world gives it.

use glam::{Vec2, Vec3};

use super::scene::{LAMP_RADIUS, LightHead};
use super::shapes::{Tri, UprightBox, push_vertical_disc};
use super::style::Appearance;
use crate::world::ActorView;
use crate::world::state::{ActorKind, LightState};

/// Add one actor's boxes, leaving out faces turned away from `eye`.
pub fn push_actor(out: &mut Vec<Tri>, actor: &ActorView, app: &Appearance, eye: Vec3) {
    let centre = actor.obb.centre.as_vec2();
    let yaw = actor.obb.yaw as f32;
    let half = actor.obb.half.as_vec2();
    let z = actor.z as f32;
    let part = |offset: f32, half: Vec2, bottom: f32, top: f32| UprightBox {
        centre: centre + Vec2::from_angle(yaw) * offset,
        yaw,
        half,
        bottom: z + bottom,
        top: z + top,
    };
    let eye = Some(eye);
    match actor.kind {
        // A prop shorter than a car (Scenario6's street barriers) is a plain block.
        ActorKind::Static if half.x < 1.5 => {
            let barrier = Vec3::new(0.75, 0.2, 0.15);
            part(0.0, half, 0.0, 1.0).push(out, barrier, app, eye);
        }
        ActorKind::Vehicle | ActorKind::Static => {
            let id = if actor.kind == ActorKind::Static {
                // Props have no id: colour them by place, which never changes.
                (centre.x.to_bits() ^ centre.y.to_bits().rotate_left(13)) | 1
            } else {
                actor.id
            };
            let body = app.car(id);
            let tyres = Vec3::splat(0.06);
            let glass = Vec3::new(0.15, 0.18, 0.22);
            part(0.0, half * Vec2::new(0.85, 0.92), 0.0, 0.35).push(out, tyres, app, eye);
            part(0.0, half, 0.3, 0.95).push(out, body, app, eye);
            let cabin = half * Vec2::new(0.55, 0.88);
            part(-0.15 * half.x, cabin, 0.95, 1.5).push(out, glass, app, eye);
        }
        ActorKind::Debris => {
            let dirt = Vec3::new(0.22, 0.19, 0.15);
            part(0.0, half, 0.0, 0.06).push(out, dirt, app, eye);
        }
        ActorKind::Walker => {
            let clothes = app.car(actor.id.wrapping_mul(7) ^ 3);
            let skin = Vec3::new(0.8, 0.62, 0.5);
            let body = Vec2::new(0.12, 0.2).min(half);
            part(0.0, body, 0.0, 1.4).push(out, clothes, app, eye);
            part(0.0, Vec2::splat(0.11), 1.4, 1.72).push(out, skin, app, eye);
        }
        ActorKind::Cyclist => {
            let frame = Vec3::splat(0.1);
            let rider = app.car(actor.id.wrapping_mul(5) ^ 1);
            part(0.0, Vec2::new(half.x, 0.05), 0.0, 0.9).push(out, frame, app, eye);
            part(-0.1, Vec2::new(0.2, 0.18), 0.9, 1.7).push(out, rider, app, eye);
        }
    }
}

/// Add the three lamps of a light head: the one for `state` lit, the others dark.
///
/// The lit lamp blooms, as an emissive light does through a camera (CARLA's RGB camera has
/// bloom on by default): it is drawn at least `bloom` metres in radius, as a disc facing the eye
/// at `eye` and set that far toward it, so its own housing never hides it. The caller sizes
/// `bloom` to a few pixels, which keeps a distant lamp from falling between pixel centres.
pub fn push_lamps(
    out: &mut Vec<Tri>,
    head: &LightHead,
    state: LightState,
    app: &Appearance,
    eye: Vec2,
    bloom: f32,
) {
    let lit = match state {
        LightState::Red => 0,
        LightState::Yellow => 1,
        LightState::Green => 2,
    };
    let colours = [
        Vec3::new(1.0, 0.1, 0.05),
        Vec3::new(1.0, 0.75, 0.05),
        Vec3::new(0.1, 1.0, 0.35),
    ];
    for (k, (&centre, colour)) in head.lamps.iter().zip(colours).enumerate() {
        if k != lit {
            let dark = app.emissive(colour * 0.18);
            push_vertical_disc(out, centre, head.facing, LAMP_RADIUS, 8, dark);
        }
    }
    let (centre, colour) = (head.lamps[lit], app.emissive(colours[lit]));
    if bloom > LAMP_RADIUS {
        let toward_eye = (eye - centre.truncate()).normalize_or(head.facing);
        let centre = centre + (toward_eye * bloom).extend(0.0);
        push_vertical_disc(out, centre, toward_eye, bloom, 8, colour);
    } else {
        push_vertical_disc(out, centre, head.facing, LAMP_RADIUS, 8, colour);
    }
}
