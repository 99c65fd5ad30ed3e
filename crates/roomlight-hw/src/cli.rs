//! The bodies of `roomlight hw …` (the binary only parses and dispatches): listing outputs,
//! showing an image on one until SIGINT or SIGTERM, and the identify pattern. It must not know
//! the agents.

use crate::frame::Frame;
use crate::identify;
use crate::output::{self, Output, OutputSelector};
use crate::window::WindowHandle;
use anyhow::{Context, Result, bail};
use std::path::Path;

/// `roomlight hw displays`: one line per output, the name first, then resolution and position.
pub fn displays(x_display: Option<&str>) -> Result<String> {
    let outputs = output::outputs(x_display)?;
    Ok(outputs.iter().map(|o| format!("{o}\n")).collect::<String>())
}

/// The image at `path` as a frame for `output`: of the output's size, or scaled to it with
/// `scale`; an image of another size is refused with both sizes named.
pub fn image_for(path: &Path, output: &Output, scale: bool) -> Result<Frame> {
    let image = image::open(path)
        .with_context(|| format!("reading {}", path.display()))?
        .to_rgb8();
    let (w, h) = image.dimensions();
    if (w, h) == (output.width, output.height) {
        return Ok(Frame::from_image(&image));
    }
    if !scale {
        bail!(
            "{} is {w}x{h} but output {} is {}x{}; give --scale to scale it",
            path.display(),
            output.name,
            output.width,
            output.height
        );
    }
    let scaled = image::imageops::resize(
        &image,
        output.width,
        output.height,
        image::imageops::FilterType::Triangle,
    );
    Ok(Frame::from_image(&scaled))
}

/// Opens a window on the output `selector` picks and shows the image at `path` on it.
pub fn open_image(
    x_display: Option<&str>,
    selector: &OutputSelector,
    path: &Path,
    scale: bool,
) -> Result<WindowHandle> {
    let outputs = output::outputs(x_display)?;
    let chosen = selector.pick(&outputs)?;
    let frame = image_for(path, chosen, scale)?;
    let window = WindowHandle::open(
        x_display,
        selector.clone(),
        &format!("roomlight {}", path.display()),
    )?;
    window.show(frame, None);
    Ok(window)
}

/// `roomlight hw show`: the image on the output until SIGINT or SIGTERM.
pub fn show(
    x_display: Option<&str>,
    selector: &OutputSelector,
    path: &Path,
    scale: bool,
) -> Result<()> {
    let window = open_image(x_display, selector, path, scale)?;
    eprintln!(
        "showing {} on {} until Ctrl-C",
        path.display(),
        window.output().name
    );
    until_stopped()
}

/// Opens the identify pattern of `projector` on the output `selector` picks, or on every
/// output when `None`.
pub fn open_identify(
    x_display: Option<&str>,
    selector: Option<&OutputSelector>,
    projector: &str,
) -> Result<Vec<WindowHandle>> {
    let outputs = output::outputs(x_display)?;
    let chosen: Vec<&Output> = match selector {
        Some(s) => vec![s.pick(&outputs)?],
        None => outputs.iter().collect(),
    };
    chosen
        .into_iter()
        .map(|o| {
            // By geometry: the output picked is the one shown on, whatever its name.
            let at = OutputSelector::Geometry(o.geometry());
            let window =
                WindowHandle::open(x_display, at, &format!("roomlight identify {}", o.name))?;
            window.show(identify::frame(projector, &o.name, o.width, o.height), None);
            Ok(window)
        })
        .collect()
}

/// `roomlight hw identify`: the identify pattern until SIGINT or SIGTERM.
pub fn identify(
    x_display: Option<&str>,
    selector: Option<&OutputSelector>,
    projector: &str,
) -> Result<()> {
    let windows = open_identify(x_display, selector, projector)?;
    for w in &windows {
        let o = w.output();
        eprintln!("identifying {o}");
    }
    until_stopped()
}

/// Blocks until SIGINT or SIGTERM.
fn until_stopped() -> Result<()> {
    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_io()
        .build()
        .context("starting the signal runtime")?;
    runtime.block_on(async {
        let mut term = tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate())
            .context("listening for SIGTERM")?;
        tokio::select! {
            r = tokio::signal::ctrl_c() => r.context("listening for SIGINT"),
            _ = term.recv() => Ok(()),
        }
    })
}
