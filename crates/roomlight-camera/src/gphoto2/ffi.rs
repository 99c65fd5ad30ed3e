//! libgphoto2 itself (Debian's libgphoto2-dev; libgphoto2 2.5's stable C ABI, soname 6): the
//! few functions the backend calls, declared by hand so that the build needs neither bindgen
//! nor libclang, and `Libgphoto2`, the `Tether` over them. Every pointer it holds is owned
//! here and released in `Drop`. It must not know settings or EXIF (the parent module does).

// The only unsafe code of the crate: calls into a C library. Each call's contract is the one
// libgphoto2 documents in gphoto2-camera.h, gphoto2-widget.h, gphoto2-file.h and
// gphoto2-port-info-list.h; the structs passed by value or filled in are laid out as there.
#![allow(unsafe_code)]

use super::{Tether, Widget};
use std::ffi::{CStr, CString, c_char, c_int, c_ulong, c_void};

#[repr(C)]
struct Opaque {
    _private: [u8; 0],
}
type Camera = Opaque;
type GpContext = Opaque;
type CameraWidget = Opaque;
type CameraFile = Opaque;
type PortInfoList = Opaque;
type AbilitiesList = Opaque;
type PortInfo = *mut c_void;

/// `CameraAbilities`, only ever filled in by the library and handed back whole: 2 504 bytes,
/// 4-aligned on Linux (measured with `sizeof`/`_Alignof` against libgphoto2 2.5.30's header).
#[repr(C, align(4))]
struct Abilities([u8; 2504]);

/// `CameraFilePath`: `char name[128]; char folder[1024];`.
#[repr(C)]
struct FilePath {
    name: [c_char; 128],
    folder: [c_char; 1024],
}

const GP_OK: c_int = 0;
const GP_CAPTURE_IMAGE: c_int = 0;
const GP_FILE_TYPE_NORMAL: c_int = 1;
const GP_WIDGET_TEXT: c_int = 2;
const GP_WIDGET_RANGE: c_int = 3;
const GP_WIDGET_TOGGLE: c_int = 4;
const GP_WIDGET_RADIO: c_int = 5;
const GP_WIDGET_MENU: c_int = 6;

#[link(name = "gphoto2")]
unsafe extern "C" {
    fn gp_context_new() -> *mut GpContext;
    fn gp_context_unref(context: *mut GpContext);
    fn gp_result_as_string(result: c_int) -> *const c_char;
    fn gp_camera_new(camera: *mut *mut Camera) -> c_int;
    fn gp_camera_set_port_info(camera: *mut Camera, info: PortInfo) -> c_int;
    fn gp_camera_set_abilities(camera: *mut Camera, abilities: Abilities) -> c_int;
    fn gp_camera_init(camera: *mut Camera, context: *mut GpContext) -> c_int;
    fn gp_camera_exit(camera: *mut Camera, context: *mut GpContext) -> c_int;
    fn gp_camera_unref(camera: *mut Camera) -> c_int;
    fn gp_camera_get_single_config(
        camera: *mut Camera,
        name: *const c_char,
        widget: *mut *mut CameraWidget,
        context: *mut GpContext,
    ) -> c_int;
    fn gp_camera_set_single_config(
        camera: *mut Camera,
        name: *const c_char,
        widget: *mut CameraWidget,
        context: *mut GpContext,
    ) -> c_int;
    fn gp_widget_get_type(widget: *mut CameraWidget, kind: *mut c_int) -> c_int;
    fn gp_widget_get_value(widget: *mut CameraWidget, value: *mut c_void) -> c_int;
    fn gp_widget_set_value(widget: *mut CameraWidget, value: *const c_void) -> c_int;
    fn gp_widget_count_choices(widget: *mut CameraWidget) -> c_int;
    fn gp_widget_get_choice(
        widget: *mut CameraWidget,
        choice_number: c_int,
        choice: *mut *const c_char,
    ) -> c_int;
    fn gp_widget_free(widget: *mut CameraWidget) -> c_int;
    fn gp_camera_capture(
        camera: *mut Camera,
        kind: c_int,
        path: *mut FilePath,
        context: *mut GpContext,
    ) -> c_int;
    fn gp_file_new(file: *mut *mut CameraFile) -> c_int;
    fn gp_file_unref(file: *mut CameraFile) -> c_int;
    fn gp_file_get_data_and_size(
        file: *mut CameraFile,
        data: *mut *const c_char,
        size: *mut c_ulong,
    ) -> c_int;
    fn gp_camera_file_get(
        camera: *mut Camera,
        folder: *const c_char,
        file: *const c_char,
        kind: c_int,
        camera_file: *mut CameraFile,
        context: *mut GpContext,
    ) -> c_int;
    fn gp_camera_file_delete(
        camera: *mut Camera,
        folder: *const c_char,
        file: *const c_char,
        context: *mut GpContext,
    ) -> c_int;
    fn gp_abilities_list_new(list: *mut *mut AbilitiesList) -> c_int;
    fn gp_abilities_list_load(list: *mut AbilitiesList, context: *mut GpContext) -> c_int;
    fn gp_abilities_list_lookup_model(list: *mut AbilitiesList, model: *const c_char) -> c_int;
    fn gp_abilities_list_get_abilities(
        list: *mut AbilitiesList,
        index: c_int,
        abilities: *mut Abilities,
    ) -> c_int;
    fn gp_abilities_list_free(list: *mut AbilitiesList) -> c_int;
}

#[link(name = "gphoto2_port")]
unsafe extern "C" {
    fn gp_port_info_list_new(list: *mut *mut PortInfoList) -> c_int;
    fn gp_port_info_list_load(list: *mut PortInfoList) -> c_int;
    fn gp_port_info_list_lookup_path(list: *mut PortInfoList, path: *const c_char) -> c_int;
    fn gp_port_info_list_get_info(list: *mut PortInfoList, n: c_int, info: *mut PortInfo) -> c_int;
    fn gp_port_info_list_free(list: *mut PortInfoList) -> c_int;
}

/// libgphoto2's message for a result code.
fn message(code: c_int) -> String {
    // SAFETY: gp_result_as_string returns a static string for every code (a generic one for
    // unknown codes), never NULL in 2.5; checked anyway.
    let text = unsafe { gp_result_as_string(code) };
    if text.is_null() {
        return format!("libgphoto2 error {code}");
    }
    // SAFETY: non-null, NUL-terminated, static.
    let text = unsafe { CStr::from_ptr(text) };
    format!("{} ({code})", text.to_string_lossy())
}

fn check(what: &str, code: c_int) -> Result<c_int, String> {
    if code < GP_OK {
        Err(format!("{what}: {}", message(code)))
    } else {
        Ok(code)
    }
}

fn c_string(s: &str) -> Result<CString, String> {
    CString::new(s).map_err(|_| format!("{s:?} contains a NUL byte"))
}

/// A camera opened through libgphoto2.
#[derive(Debug)]
pub struct Libgphoto2 {
    camera: *mut Camera,
    context: *mut GpContext,
}

// SAFETY: libgphoto2's camera and context may be used from any thread, one at a time; the
// backend moves this to its camera thread and never shares it.
unsafe impl Send for Libgphoto2 {}

impl Drop for Libgphoto2 {
    fn drop(&mut self) {
        // SAFETY: both pointers were returned by gp_camera_new / gp_context_new, are non-null
        // (checked in `open`), and are released exactly once, here.
        unsafe {
            gp_camera_exit(self.camera, self.context);
            gp_camera_unref(self.camera);
            gp_context_unref(self.context);
        }
    }
}

impl Libgphoto2 {
    /// Opens the camera at `port` (`usb:001,004`, `ptpip:192.168.1.2`, `disk:/DIR` for
    /// libgphoto2's "Directory Browse" driver), or the first camera found.
    pub fn open(port: Option<&str>) -> Result<Self, String> {
        // SAFETY: gp_context_new has no preconditions; NULL is checked.
        let context = unsafe { gp_context_new() };
        if context.is_null() {
            return Err("gp_context_new failed".into());
        }
        let mut camera = std::ptr::null_mut();
        // SAFETY: `camera` is a valid out-pointer.
        if let Err(e) = check("gp_camera_new", unsafe { gp_camera_new(&mut camera) }) {
            // SAFETY: the context was created above and is released once.
            unsafe { gp_context_unref(context) };
            return Err(e);
        }
        // From here `Drop` releases both, whatever fails.
        let this = Self { camera, context };
        if let Some(port) = port {
            this.set_port(port)?;
            // The disk: port is only ever the "Directory Browse" driver, which
            // autodetection (USB only) never picks.
            if port.starts_with("disk:") {
                this.set_model("Directory Browse")?;
            }
        }
        // SAFETY: camera and context are valid; init autodetects the model when none is set.
        check("gp_camera_init", unsafe {
            gp_camera_init(this.camera, this.context)
        })?;
        Ok(this)
    }

    fn set_port(&self, port: &str) -> Result<(), String> {
        let path = c_string(port)?;
        let mut list = std::ptr::null_mut();
        // SAFETY: `list` is a valid out-pointer; on success it is freed below, once.
        check("gp_port_info_list_new", unsafe {
            gp_port_info_list_new(&mut list)
        })?;
        let result = (|| {
            // SAFETY: `list` is a valid list; `path` outlives the calls; `info` is owned by
            // the list and copied by gp_camera_set_port_info before the list is freed.
            unsafe {
                check("gp_port_info_list_load", gp_port_info_list_load(list))?;
                let index = gp_port_info_list_lookup_path(list, path.as_ptr());
                if index < GP_OK {
                    return Err(format!(
                        "no port {port} (gphoto2 --list-ports shows them): {}",
                        message(index)
                    ));
                }
                let mut info: PortInfo = std::ptr::null_mut();
                check(
                    "gp_port_info_list_get_info",
                    gp_port_info_list_get_info(list, index, &mut info),
                )?;
                check(
                    "gp_camera_set_port_info",
                    gp_camera_set_port_info(self.camera, info),
                )?;
            }
            Ok(())
        })();
        // SAFETY: created above, freed once.
        unsafe { gp_port_info_list_free(list) };
        result
    }

    fn set_model(&self, model: &str) -> Result<(), String> {
        let name = c_string(model)?;
        let mut list = std::ptr::null_mut();
        // SAFETY: `list` is a valid out-pointer; on success it is freed below, once.
        check("gp_abilities_list_new", unsafe {
            gp_abilities_list_new(&mut list)
        })?;
        let result = (|| {
            // SAFETY: `list` is valid; `abilities` is a correctly sized and aligned buffer the
            // library fills in, then passed back by value as the header declares.
            unsafe {
                check(
                    "gp_abilities_list_load",
                    gp_abilities_list_load(list, self.context),
                )?;
                let index = check(
                    "gp_abilities_list_lookup_model",
                    gp_abilities_list_lookup_model(list, name.as_ptr()),
                )?;
                let mut abilities = Abilities([0; 2504]);
                check(
                    "gp_abilities_list_get_abilities",
                    gp_abilities_list_get_abilities(list, index, &mut abilities),
                )?;
                check(
                    "gp_camera_set_abilities",
                    gp_camera_set_abilities(self.camera, abilities),
                )?;
            }
            Ok(())
        })();
        // SAFETY: created above, freed once.
        unsafe { gp_abilities_list_free(list) };
        result
    }

    /// Runs `f` on the widget called `name`, freed afterwards; `Ok(None)` when the camera
    /// has no such widget (or no configuration at all).
    fn with_widget<T>(
        &mut self,
        name: &str,
        f: impl FnOnce(*mut CameraWidget) -> Result<T, String>,
    ) -> Result<Option<T>, String> {
        let key = c_string(name)?;
        let mut widget = std::ptr::null_mut();
        // SAFETY: camera and context are valid, `widget` is a valid out-pointer.
        let code = unsafe {
            gp_camera_get_single_config(self.camera, key.as_ptr(), &mut widget, self.context)
        };
        if code < GP_OK || widget.is_null() {
            return Ok(None);
        }
        let result = f(widget);
        // SAFETY: the widget came from gp_camera_get_single_config and is freed once.
        unsafe { gp_widget_free(widget) };
        result.map(Some)
    }
}

/// A widget's value and choices as text.
fn read_widget(widget: *mut CameraWidget) -> Result<Widget, String> {
    let mut kind: c_int = -1;
    // SAFETY (whole function): `widget` is a live widget; the value out-pointers match the
    // widget's type as gphoto2-widget.h specifies (char* for text, radio and menu; float for
    // range; int for toggle); strings are owned by the widget and copied before it is freed.
    unsafe {
        check("gp_widget_get_type", gp_widget_get_type(widget, &mut kind))?;
        let value = match kind {
            GP_WIDGET_TEXT | GP_WIDGET_RADIO | GP_WIDGET_MENU => {
                let mut text: *const c_char = std::ptr::null();
                check(
                    "gp_widget_get_value",
                    gp_widget_get_value(widget, (&raw mut text).cast()),
                )?;
                if text.is_null() {
                    String::new()
                } else {
                    CStr::from_ptr(text).to_string_lossy().into_owned()
                }
            }
            GP_WIDGET_RANGE => {
                let mut v: f32 = 0.0;
                check(
                    "gp_widget_get_value",
                    gp_widget_get_value(widget, (&raw mut v).cast()),
                )?;
                v.to_string()
            }
            GP_WIDGET_TOGGLE => {
                let mut v: c_int = 0;
                check(
                    "gp_widget_get_value",
                    gp_widget_get_value(widget, (&raw mut v).cast()),
                )?;
                v.to_string()
            }
            other => return Err(format!("a widget of type {other} has no value")),
        };
        let mut choices = Vec::new();
        if matches!(kind, GP_WIDGET_RADIO | GP_WIDGET_MENU) {
            let n = gp_widget_count_choices(widget).max(0);
            for i in 0..n {
                let mut choice: *const c_char = std::ptr::null();
                if gp_widget_get_choice(widget, i, &mut choice) >= GP_OK && !choice.is_null() {
                    choices.push(CStr::from_ptr(choice).to_string_lossy().into_owned());
                }
            }
        }
        Ok(Widget { value, choices })
    }
}

impl Tether for Libgphoto2 {
    fn widget(&mut self, name: &str) -> Result<Option<Widget>, String> {
        self.with_widget(name, read_widget)
    }

    fn set(&mut self, name: &str, value: &str) -> Result<(), String> {
        let key = c_string(name)?;
        let text = c_string(value)?;
        let (camera, context) = (self.camera, self.context);
        self.with_widget(name, |widget| {
            let mut kind: c_int = -1;
            // SAFETY: `widget` is live; the value passed matches its type (the string itself
            // for text types, a float for ranges), copied by the library; camera and context
            // are valid.
            unsafe {
                check("gp_widget_get_type", gp_widget_get_type(widget, &mut kind))?;
                if kind == GP_WIDGET_RANGE {
                    let v: f32 = value
                        .parse()
                        .map_err(|_| format!("{value:?} is not a number"))?;
                    check(
                        "gp_widget_set_value",
                        gp_widget_set_value(widget, (&raw const v).cast()),
                    )?;
                } else {
                    check(
                        "gp_widget_set_value",
                        gp_widget_set_value(widget, text.as_ptr().cast()),
                    )?;
                }
                check(
                    "gp_camera_set_single_config",
                    gp_camera_set_single_config(camera, key.as_ptr(), widget, context),
                )?;
            }
            Ok(())
        })?
        .ok_or_else(|| format!("the camera has no {name}"))
    }

    fn capture(&mut self) -> Result<(String, Vec<u8>), String> {
        let mut path = FilePath {
            name: [0; 128],
            folder: [0; 1024],
        };
        // SAFETY (whole block): camera and context are valid; `path` is a correctly laid out
        // buffer the library fills with NUL-terminated strings; `file` is created and freed
        // here once; the data pointer is owned by `file` and copied before it is freed.
        unsafe {
            check(
                "gp_camera_capture",
                gp_camera_capture(self.camera, GP_CAPTURE_IMAGE, &mut path, self.context),
            )?;
            path.name[127] = 0;
            path.folder[1023] = 0;
            let name = CStr::from_ptr(path.name.as_ptr());
            let folder = CStr::from_ptr(path.folder.as_ptr());
            let mut file = std::ptr::null_mut();
            check("gp_file_new", gp_file_new(&mut file))?;
            let result = (|| {
                check(
                    "gp_camera_file_get",
                    gp_camera_file_get(
                        self.camera,
                        folder.as_ptr(),
                        name.as_ptr(),
                        GP_FILE_TYPE_NORMAL,
                        file,
                        self.context,
                    ),
                )?;
                let mut data: *const c_char = std::ptr::null();
                let mut size: c_ulong = 0;
                check(
                    "gp_file_get_data_and_size",
                    gp_file_get_data_and_size(file, &mut data, &mut size),
                )?;
                if data.is_null() || size == 0 {
                    return Err("the camera sent an empty file".to_string());
                }
                let len = usize::try_from(size).map_err(|_| "file too large".to_string())?;
                Ok(std::slice::from_raw_parts(data.cast::<u8>(), len).to_vec())
            })();
            gp_file_unref(file);
            // Shots are not kept on the card: a session takes thousands.
            gp_camera_file_delete(self.camera, folder.as_ptr(), name.as_ptr(), self.context);
            Ok((name.to_string_lossy().into_owned(), result?))
        }
    }
}
