//! Why no Vulkan adapter is usable: what was found of the loader and the
//! drivers (ICD manifests), and so what is missing. The messages name the
//! files they looked for instead of always suggesting an install.

use std::path::{Path, PathBuf};

/// Folders the Vulkan loader reads driver manifests from (Linux).
const ICD_FOLDERS: [&str; 3] = [
    "/usr/share/vulkan/icd.d",
    "/usr/local/share/vulkan/icd.d",
    "/etc/vulkan/icd.d",
];

/// The loader library.
const LOADER: &str = "libvulkan.so.1";

/// What was found on this machine.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Found {
    /// The loader library, if found.
    pub loader: Option<PathBuf>,
    /// Driver manifests (from `VK_DRIVER_FILES`/`VK_ICD_FILENAMES` when set).
    pub drivers: Vec<PathBuf>,
    /// The variable that overrode the manifest folders, if any.
    pub override_var: Option<&'static str>,
    /// The manifests among `drivers` that do not exist on disk.
    pub missing: Vec<PathBuf>,
}

/// Looks for the loader and the driver manifests.
pub fn look() -> Found {
    let mut folders: Vec<PathBuf> = std::env::var("LD_LIBRARY_PATH")
        .unwrap_or_default()
        .split(':')
        .filter(|p| !p.is_empty())
        .map(PathBuf::from)
        .collect();
    for root in ["/usr/lib", "/lib", "/usr/lib64", "/lib64", "/usr/local/lib"] {
        folders.push(PathBuf::from(root));
        // Multiarch folders, e.g. /usr/lib/x86_64-linux-gnu.
        if let Ok(entries) = std::fs::read_dir(root) {
            for e in entries.flatten() {
                if e.file_name().to_string_lossy().ends_with("-linux-gnu") {
                    folders.push(e.path());
                }
            }
        }
    }
    let loader = folders.iter().map(|f| f.join(LOADER)).find(|p| p.exists());
    let override_var = ["VK_DRIVER_FILES", "VK_ICD_FILENAMES"]
        .into_iter()
        .find(|v| std::env::var(v).is_ok_and(|s| !s.is_empty()));
    let drivers = match override_var {
        Some(var) => std::env::var(var)
            .unwrap_or_default()
            .split(':')
            .filter(|p| !p.is_empty())
            .map(PathBuf::from)
            .collect(),
        None => {
            let mut found: Vec<PathBuf> = ICD_FOLDERS
                .iter()
                .filter_map(|f| std::fs::read_dir(f).ok())
                .flat_map(|entries| entries.flatten().map(|e| e.path()))
                .filter(|p| p.extension().is_some_and(|e| e == "json"))
                .collect();
            found.sort();
            found.dedup();
            found
        }
    };
    let missing = not_on_disk(&drivers);
    Found {
        loader,
        drivers,
        override_var,
        missing,
    }
}

/// The paths among `paths` that do not exist.
fn not_on_disk(paths: &[PathBuf]) -> Vec<PathBuf> {
    paths
        .iter()
        .filter(|p| !Path::new(p).exists())
        .cloned()
        .collect()
}

fn names(paths: &[PathBuf]) -> String {
    paths
        .iter()
        .map(|p| {
            p.file_name().map_or_else(
                || p.display().to_string(),
                |n| n.to_string_lossy().into_owned(),
            )
        })
        .collect::<Vec<_>>()
        .join(", ")
}

/// The message for "no adapter": what was found and what is missing. It
/// reads nothing from the machine: [`look`] does.
pub fn explain(found: &Found) -> String {
    let Some(loader) = &found.loader else {
        return format!(
            "no Vulkan adapter: the Vulkan loader ({LOADER}) is not installed (looked in \
             LD_LIBRARY_PATH and the system library folders); install it and a driver, e.g. \
             `apt-get install libvulkan1 mesa-vulkan-drivers` (Mesa's lavapipe runs on any CPU)"
        );
    };
    if found.drivers.is_empty() {
        return match found.override_var {
            Some(var) => format!(
                "no Vulkan adapter: loader {} found, but {var} is set and names no driver \
                 manifest; unset it or point it at one",
                loader.display()
            ),
            None => format!(
                "no Vulkan adapter: loader {} found, but no driver manifest (ICD) in {}; install \
                 a driver, e.g. `apt-get install mesa-vulkan-drivers` (lavapipe runs on any CPU)",
                loader.display(),
                ICD_FOLDERS.join(", ")
            ),
        };
    }
    let mut text = format!(
        "no Vulkan adapter: loader {} and drivers {}{} found, but none of them gave an adapter \
         (a driver for other hardware, or one that failed to start: VK_LOADER_DEBUG=error shows \
         why)",
        loader.display(),
        names(&found.drivers),
        found
            .override_var
            .map_or(String::new(), |v| format!(" (from {v})")),
    );
    if !found.missing.is_empty() {
        text += &format!("; these manifests do not exist: {}", names(&found.missing));
    }
    text
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Each situation names what was found and what to do, and only the
    /// ones that lack a piece suggest installing it. The cases are data:
    /// nothing here depends on what this machine has installed.
    #[test]
    fn the_message_follows_what_was_found() {
        let none = explain(&Found::default());
        assert!(
            none.contains("loader (libvulkan.so.1) is not installed"),
            "{none}"
        );
        assert!(none.contains("libvulkan1 mesa-vulkan-drivers"), "{none}");
        let loader = Some(PathBuf::from("/usr/lib/x86_64-linux-gnu/libvulkan.so.1"));
        let no_driver = explain(&Found {
            loader: loader.clone(),
            ..Found::default()
        });
        assert!(
            no_driver.contains("found, but no driver manifest"),
            "{no_driver}"
        );
        assert!(no_driver.contains("mesa-vulkan-drivers"), "{no_driver}");
        let overridden = explain(&Found {
            loader: loader.clone(),
            drivers: vec![],
            override_var: Some("VK_ICD_FILENAMES"),
            missing: vec![],
        });
        assert!(
            overridden.contains("VK_ICD_FILENAMES is set"),
            "{overridden}"
        );
        let both = explain(&Found {
            loader,
            drivers: vec![
                PathBuf::from("/usr/share/vulkan/icd.d/lvp_icd.x86_64.json"),
                PathBuf::from("/nowhere/gone.json"),
            ],
            override_var: Some("VK_DRIVER_FILES"),
            missing: vec![PathBuf::from("/nowhere/gone.json")],
        });
        assert!(
            both.contains("drivers lvp_icd.x86_64.json, gone.json (from VK_DRIVER_FILES) found"),
            "{both}"
        );
        assert!(both.contains("do not exist: gone.json"), "{both}");
        assert!(
            !both.contains("apt-get"),
            "installed pieces are not suggested: {both}"
        );
    }

    /// The manifests `look` reports as missing are exactly those not on
    /// disk (here: one written to a scratch folder, one that is not).
    #[test]
    fn only_absent_manifests_are_missing() {
        let dir = tempfile::tempdir().unwrap();
        let here = dir.path().join("here.json");
        std::fs::write(&here, "{}").unwrap();
        let gone = dir.path().join("gone.json");
        assert_eq!(not_on_disk(&[here, gone.clone()]), vec![gone]);
    }
}
