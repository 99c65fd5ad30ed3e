//! The outputs (monitors, projectors) of an X screen as RandR reports them, and choosing one by
//! name, index or geometry. It must not know windows or what is shown on them.

use crate::HwError;
use crate::x11::X11;
use std::fmt;
use std::str::FromStr;
use x11rb::connection::RequestConnection;
use x11rb::protocol::randr::{self, ConnectionExt as _};
use x11rb::protocol::xproto::ConnectionExt as _;

/// One output: a region of the X screen that one projector shows.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Output {
    /// RandR's monitor name, e.g. `HDMI-1`.
    pub name: String,
    pub width: u32,
    pub height: u32,
    pub x: i32,
    pub y: i32,
    pub primary: bool,
}

impl Output {
    /// `WxH+X+Y`, as xrandr writes it.
    pub fn geometry(&self) -> Geometry {
        Geometry {
            width: self.width,
            height: self.height,
            x: self.x,
            y: self.y,
        }
    }
}

impl fmt::Display for Output {
    /// One line of `roomlight hw displays`: the name first, then resolution and position.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{} {}x{} +{}+{}{}",
            self.name,
            self.width,
            self.height,
            self.x,
            self.y,
            if self.primary { " primary" } else { "" }
        )
    }
}

/// A rectangle of the screen, `WxH+X+Y`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Geometry {
    pub width: u32,
    pub height: u32,
    pub x: i32,
    pub y: i32,
}

impl fmt::Display for Geometry {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}x{}+{}+{}", self.width, self.height, self.x, self.y)
    }
}

impl FromStr for Geometry {
    type Err = HwError;
    fn from_str(s: &str) -> Result<Self, HwError> {
        let bad = || HwError::Selector(format!("{s:?}: expected a geometry WxH+X+Y"));
        let (size, rest) = s.split_once('+').ok_or_else(bad)?;
        let (w, h) = size.split_once('x').ok_or_else(bad)?;
        let (x, y) = rest.split_once('+').ok_or_else(bad)?;
        let parse = |t: &str| t.parse::<u32>().map_err(|_| bad());
        let geometry = Self {
            width: parse(w)?,
            height: parse(h)?,
            x: x.parse().map_err(|_| bad())?,
            y: y.parse().map_err(|_| bad())?,
        };
        if geometry.width == 0 || geometry.height == 0 {
            return Err(bad());
        }
        Ok(geometry)
    }
}

/// Which output a display goes on: `HDMI-1` (a name), `1` (an index into the list) or
/// `320x240+320+0` (a geometry).
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum OutputSelector {
    Name(String),
    Index(usize),
    Geometry(Geometry),
}

impl FromStr for OutputSelector {
    type Err = HwError;
    fn from_str(s: &str) -> Result<Self, HwError> {
        let s = s.trim();
        if s.is_empty() {
            return Err(HwError::Selector("an empty output".into()));
        }
        if let Ok(i) = s.parse::<usize>() {
            return Ok(Self::Index(i));
        }
        let looks_like_geometry = s.contains('+')
            && s.chars()
                .all(|c| c.is_ascii_digit() || c == 'x' || c == '+' || c == '-');
        if looks_like_geometry {
            return s.parse().map(Self::Geometry);
        }
        Ok(Self::Name(s.to_string()))
    }
}

impl fmt::Display for OutputSelector {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Name(n) => f.write_str(n),
            Self::Index(i) => write!(f, "output #{i}"),
            Self::Geometry(g) => write!(f, "the output at {g}"),
        }
    }
}

impl OutputSelector {
    /// The output this selects among `outputs`; refused with the outputs there are.
    pub fn pick<'a>(&self, outputs: &'a [Output]) -> Result<&'a Output, HwError> {
        let found = match self {
            Self::Name(n) => outputs.iter().find(|o| &o.name == n),
            Self::Index(i) => outputs.get(*i),
            Self::Geometry(g) => outputs.iter().find(|o| o.geometry() == *g),
        };
        found.ok_or_else(|| HwError::NoSuchOutput {
            wanted: self.to_string(),
            there: outputs
                .iter()
                .enumerate()
                .map(|(i, o)| format!("#{i} {o}"))
                .collect::<Vec<_>>()
                .join(", "),
        })
    }
}

/// The outputs of `display` (or `$DISPLAY`), as [`list`] gives them.
pub fn outputs(display: Option<&str>) -> Result<Vec<Output>, HwError> {
    list(&X11::connect(display)?)
}

/// The screen's active outputs, in RandR's order (the index of `OutputSelector::Index`). A
/// server without RandR 1.5 monitors has one output: the whole screen, named `screen`.
pub(crate) fn list(x: &X11) -> Result<Vec<Output>, HwError> {
    let failed = |e: String| HwError::Request(format!("listing outputs: {e}"));
    let screen = x.screen();
    let whole = || Output {
        name: "screen".into(),
        width: u32::from(screen.width_in_pixels),
        height: u32::from(screen.height_in_pixels),
        x: 0,
        y: 0,
        primary: true,
    };
    let has_randr = x
        .conn
        .extension_information(randr::X11_EXTENSION_NAME)
        .map_err(|e| failed(e.to_string()))?
        .is_some();
    if !has_randr {
        return Ok(vec![whole()]);
    }
    let version = x
        .conn
        .randr_query_version(1, 5)
        .map_err(|e| failed(e.to_string()))?
        .reply()
        .map_err(|e| failed(e.to_string()))?;
    if (version.major_version, version.minor_version) < (1, 5) {
        return Ok(vec![whole()]);
    }
    let monitors = x
        .conn
        .randr_get_monitors(x.root(), true)
        .map_err(|e| failed(e.to_string()))?
        .reply()
        .map_err(|e| failed(e.to_string()))?
        .monitors;
    let mut outputs = Vec::with_capacity(monitors.len());
    for m in monitors {
        let name = x
            .conn
            .get_atom_name(m.name)
            .map_err(|e| failed(e.to_string()))?
            .reply()
            .map_err(|e| failed(e.to_string()))?
            .name;
        outputs.push(Output {
            name: String::from_utf8_lossy(&name).into_owned(),
            width: u32::from(m.width),
            height: u32::from(m.height),
            x: i32::from(m.x),
            y: i32::from(m.y),
            primary: m.primary,
        });
    }
    if outputs.is_empty() {
        outputs.push(whole());
    }
    Ok(outputs)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn outputs() -> Vec<Output> {
        ["A", "B"]
            .iter()
            .enumerate()
            .map(|(i, n)| Output {
                name: (*n).into(),
                width: 320,
                height: 240,
                x: 320 * i as i32,
                y: 0,
                primary: i == 0,
            })
            .collect()
    }

    #[test]
    fn selectors_parse() {
        assert_eq!("HDMI-1".parse(), Ok(OutputSelector::Name("HDMI-1".into())));
        assert_eq!("1".parse(), Ok(OutputSelector::Index(1)));
        assert_eq!(
            "320x240+320+0".parse(),
            Ok(OutputSelector::Geometry(Geometry {
                width: 320,
                height: 240,
                x: 320,
                y: 0
            }))
        );
        assert!("0x240+0+0".parse::<OutputSelector>().is_err());
        assert!("".parse::<OutputSelector>().is_err());
    }

    #[test]
    fn picks_by_name_index_and_geometry_and_names_what_there_is() {
        let o = outputs();
        let by = |s: &str| {
            s.parse::<OutputSelector>()
                .and_then(|s| s.pick(&o).cloned())
        };
        assert_eq!(by("B").map(|o| o.x), Ok(320));
        assert_eq!(by("0").map(|o| o.name), Ok("A".into()));
        assert_eq!(by("320x240+320+0").map(|o| o.name), Ok("B".into()));
        let err = by("HDMI-9").expect_err("no HDMI-9").to_string();
        assert!(
            err.contains("HDMI-9") && err.contains("#1 B 320x240 +320+0"),
            "{err}"
        );
    }

    #[test]
    fn a_line_starts_with_the_name() {
        assert_eq!(outputs()[1].to_string(), "B 320x240 +320+0");
        assert_eq!(outputs()[0].to_string(), "A 320x240 +0+0 primary");
    }
}
