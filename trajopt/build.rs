//! Links IPOPT's C interface: Debian's `coinor-libipopt1v5` (scripts/apt-packages.txt),
//! which pulls in MUMPS, LAPACK and BLAS. By its soname, so only the runtime package is
//! needed (no `libipopt.so` development link), on arm64 too: there the library is in the
//! multiarch directory (on this machine: scripts/arm64-ipopt.sh).
fn main() {
    let dir = match std::env::var("TARGET").as_deref() {
        Ok("aarch64-unknown-linux-gnu") => "/usr/lib/aarch64-linux-gnu",
        _ => "/usr/lib",
    };
    println!("cargo:rustc-link-search=native={dir}");
    println!("cargo:rustc-link-lib=dylib:+verbatim=libipopt.so.1");
    println!("cargo:rerun-if-changed=build.rs");
}
