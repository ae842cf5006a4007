// joltc-sys links Jolt and JoltC but not the C++ standard library they are built on.
fn main() {
    let os = std::env::var("CARGO_CFG_TARGET_OS").unwrap_or_default();
    let library = if os == "macos" { "c++" } else { "stdc++" };
    println!("cargo:rustc-link-lib={library}");
}
