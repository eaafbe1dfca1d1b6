//! Each Embree's batch calls timed on one thread (which ones the backend
//! uses for coherent and incoherent batches were chosen from these numbers,
//! `embree::Major::default_batch_modes`), and native's batch call against
//! the fastest of them per ray kind, so that native is compared with each
//! Embree at its best and not only with the calls the backend uses.
//!
//! Every call of the major (a loop of single rays; Embree 3's streams;
//! packets of 4, 8 and 16) is timed on its own, with the coherent flag for
//! camera and shadow rays and with the incoherent flag for every ray kind:
//! on the large meshes Embree 3's incoherent stream is its fastest shadow
//! call (1 thread, Mrays/s, coherent / incoherent stream: sphere:1M 6.39 /
//! 8.95, grass:500k 0.60 / 1.21, subdiv:bunny:500k 4.72 / 7.58; cow 26.0 /
//! 16.1). The fastest call is then timed again with native's, their passes
//! alternating: a call timed alone runs on caches and TLB entries its
//! previous pass left warm, while native's main-table number alternates
//! with every other contender, and on arch:2M's diffuse rays that alone
//! read Embree 4's packets about 20 % faster than the same calls alternating.

use super::ray_sets::RaySets;
use super::tables::BestCall;
use super::timing::{throughput, throughputs_by_call, RayKind, RaySet};
use super::Contender;
use crate::accel::embree::{BatchMode, EmbreeBackend, Major, Quality};
use crate::accel::{BackendKind, Traversal};
use crate::error::Result;
use crate::scene::Scene;
use std::fmt::Write as _;

/// `major`'s batch calls on `scene`'s rays, as rows of the batch-call table
/// (`rows`), and per ray kind its fastest call timed against `native`'s
/// batch call, `passes` rounds alternating (`best`).
pub(super) fn embree_calls(major: Major, scene: &Scene, native: Option<&dyn Traversal>, rays: &RaySets, passes: usize, rows: &mut String, best: &mut Vec<BestCall>) -> Result<()> {
    let mut e = EmbreeBackend::build(major, &scene.shapes, 1, Quality::Medium)?;
    let embree = Contender::Backend(if major == Major::V3 { BackendKind::Embree3 } else { BackendKind::Embree4 });
    // (label, rays, coherent call, incoherent call); native's call is the
    // main table's: the coherent one where there is one.
    for (label, rays, coherent, incoherent) in [
        ("camera", rays.get(RaySet::Camera), Some(RayKind::Camera), RayKind::Random),
        ("shadow", rays.get(RaySet::Shadow), Some(RayKind::Shadow), RayKind::ShadowIncoherent),
        ("random", rays.get(RaySet::Random), None, RayKind::Random),
        ("diffuse", rays.get(RaySet::Diffuse), None, RayKind::Random),
    ] {
        let mut cells = Vec::new();
        let mut top: Option<(f64, BatchMode, RayKind, &str)> = None;
        // A column pair for every call the table's header names; a call
        // this major lacks reads as dashes.
        for &mode in BatchMode::EVERY {
            if !BatchMode::all(major).contains(&mode) {
                cells.extend(["–".to_string(), "–".to_string()]);
                continue;
            }
            e.set_batch_modes(mode, mode);
            for (kind, flag) in [(coherent, "c"), (Some(incoherent), "i")] {
                let Some(kind) = kind else {
                    cells.push("–".to_string());
                    continue;
                };
                let m = throughput(&e, rays, kind, 1, 3);
                if top.is_none_or(|t| m > t.0) {
                    top = Some((m, mode, kind, flag));
                }
                cells.push(format!("{m:.2}"));
            }
        }
        let _ = writeln!(rows, "| {} | embree{} | {label} | {} |", scene.name, major.number(), cells.join(" | "));
        let Some((_, mode, kind, flag)) = top else { continue };
        e.set_batch_modes(mode, mode);
        let paired = native.map(|n| {
            let m = throughputs_by_call(&[(n, coherent.unwrap_or(incoherent)), (&e, kind)], rays, 1, passes);
            (m[0], m[1])
        });
        best.push(BestCall { scene: scene.name.clone(), rays: label, embree, call: format!("{} {flag}", mode.name()), paired });
    }
    Ok(())
}

