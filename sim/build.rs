//! Links IPOPT's C interface (Debian `coinor-libipopt-dev`, see
//! scripts/apt-packages.txt). The shared library pulls in MUMPS, LAPACK and BLAS.
fn main() {
    println!("cargo:rustc-link-search=native=/usr/lib");
    println!("cargo:rustc-link-lib=dylib=ipopt");
    println!("cargo:rerun-if-changed=build.rs");
}
