//! Writes eye-height cells in the free space of a scene (e.g. a real city's streets):
//! `cargo run --release --example free_cells -- SCENE COUNT SIZE HEIGHT OUT.json [SEED]`.
use glam::Vec3;
use std::path::Path;

fn main() -> Result<(), String> {
    let a: Vec<String> = std::env::args().collect();
    if a.len() < 6 {
        return Err("usage: free_cells SCENE COUNT SIZE HEIGHT OUT.json [SEED]".into());
    }
    let scene = umbrasweep::scene::load(Path::new(&a[1])).map_err(|e| e.to_string())?;
    let count: usize = a[2].parse().map_err(|e| format!("COUNT: {e}"))?;
    let size: f32 = a[3].parse().map_err(|e| format!("SIZE: {e}"))?;
    let height: f32 = a[4].parse().map_err(|e| format!("HEIGHT: {e}"))?;
    let seed: u64 = a.get(6).map(|s| s.parse().unwrap_or(1)).unwrap_or(1);
    let bounds: Vec<_> = scene.objects.iter().map(|o| o.bounds).collect();
    let cells =
        umbrasweep::cells::free_cells(&bounds, count, Vec3::new(size, 2.0, size), height, seed);
    umbrasweep::cells::save_json(Path::new(&a[5]), &cells).map_err(|e| e.to_string())?;
    println!("{} cells written to {}", cells.len(), a[5]);
    Ok(())
}
