//! Structured light on real photographs as files: the patterns of a projector written as PNG
//! with their manifest, and a folder of captures decoded into a correspondence map. The bodies
//! of `roomlight graycode generate|decode`; the binary only parses and prints.

use anyhow::{Context, Result, bail};
use roomlight_calib::graycode::{DecodeConfig, Manifest, decode};
use roomlight_calib::image_io::{Depth, Encoding, LinearImage};
use std::collections::HashMap;
use std::path::Path;

/// Writes the patterns of a `width`×`height` projector as PNG files and `out/patterns.json`;
/// returns what it wrote, for the command to print.
pub fn generate(width: u32, height: u32, out: &Path) -> Result<String> {
    let manifest = Manifest::new(width, height)?;
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    for p in &manifest.patterns {
        manifest
            .pattern_image(p.pattern)
            .save_png_srgb8(&out.join(&p.file))?;
    }
    let json = out.join("patterns.json");
    std::fs::write(&json, serde_json::to_string_pretty(&manifest)?)
        .with_context(|| format!("writing {}", json.display()))?;
    Ok(format!(
        "{} patterns for a {width}x{height} projector in {}",
        manifest.patterns.len(),
        out.display()
    ))
}

/// Decodes a folder of captures named like the patterns of `patterns` into a 16-bit map at
/// `out`; every listed capture must be there, of one size, and no other PNG. Returns what it
/// decoded, for the command to print.
pub fn decode_folder(
    patterns: &Path,
    captures: &Path,
    out: &Path,
    encoding: Encoding,
    depth: Depth,
) -> Result<String> {
    let text = std::fs::read_to_string(patterns)
        .with_context(|| format!("reading {}", patterns.display()))?;
    let manifest: Manifest = serde_json::from_str(&text)
        .with_context(|| format!("{}: not a pattern manifest", patterns.display()))?;
    manifest.validate(&patterns.display().to_string())?;
    // Every listed file must be there, and nothing else that looks like a capture.
    let listed: Vec<&str> = manifest.patterns.iter().map(|p| p.file.as_str()).collect();
    let entries = std::fs::read_dir(captures)
        .with_context(|| format!("reading the folder {}", captures.display()))?;
    for entry in entries {
        let name = entry?.file_name().to_string_lossy().into_owned();
        if name.to_ascii_lowercase().ends_with(".png") && !listed.contains(&name.as_str()) {
            bail!(
                "{}: extra file {name}: it is not in {}",
                captures.display(),
                patterns.display()
            );
        }
    }
    let mut images: HashMap<String, LinearImage> = HashMap::new();
    let mut size = None;
    for file in &listed {
        let path = captures.join(file);
        if !path.exists() {
            bail!(
                "{}: missing capture {file} listed in {}",
                captures.display(),
                patterns.display()
            );
        }
        let img = LinearImage::load_png(&path, encoding, depth)?;
        match size {
            None => size = Some((img.width, img.height)),
            Some((w, h)) => img.expect_size(w, h, &path.display().to_string())?,
        }
        images.insert((*file).to_string(), img);
    }
    let decoded = decode(&manifest, &DecodeConfig::default(), |p| {
        images
            .get(&p.file)
            .ok_or_else(|| roomlight_calib::CalibError::File {
                file: p.file.clone(),
                problem: "missing".into(),
            })
    })?;
    let data = decoded.to_png16();
    image::ImageBuffer::<image::Rgb<u16>, Vec<u16>>::from_raw(decoded.width, decoded.height, data)
        .context("map buffer")?
        .save(out)
        .with_context(|| format!("writing {}", out.display()))?;
    Ok(format!(
        "decoded {:.1}% of {} camera pixels into {}",
        100.0 * decoded.decoded_share(),
        decoded.map.len(),
        out.display()
    ))
}
