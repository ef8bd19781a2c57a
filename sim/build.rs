//! With feature `mujoco`: the MuJoCo library is found at run time through an rpath to the
//! folder mujoco-rs links from (`MUJOCO_DYNAMIC_LINK_DIR`, set by `.cargo/config.toml`).
fn main() {
    println!("cargo::rerun-if-env-changed=MUJOCO_DYNAMIC_LINK_DIR");
    if std::env::var_os("CARGO_FEATURE_MUJOCO").is_none() {
        return;
    }
    match std::env::var("MUJOCO_DYNAMIC_LINK_DIR") {
        Ok(dir) if std::path::Path::new(&dir).join("libmujoco.so").is_file() => {
            println!("cargo::rustc-link-arg=-Wl,-rpath,{dir}");
        }
        Ok(dir) => panic!(
            "feature `mujoco`: {dir}/libmujoco.so is missing; run scripts/fetch-mujoco.sh first"
        ),
        Err(_) => panic!(
            "feature `mujoco`: MUJOCO_DYNAMIC_LINK_DIR is not set (.cargo/config.toml sets it); \
             run scripts/fetch-mujoco.sh first"
        ),
    }
}
