"""The shell material the shell and fit tests share: a realistic medium-weight woven."""

from yarnfit.shell import ShellMaterial

H = 3.0e-4  # m: a medium-weight woven fabric
# h s00 = 1000 N/m, h³ b00 = 1e-5 N·m; weft stiffer than warp, b01 ≠ 0.
FABRIC = ShellMaterial(
    thickness=H,
    s00=1.0e3 / H,
    s01=1.2e2 / H,
    s11=6.0e2 / H,
    s22=5.0e1 / H,
    b00=1.0e-5 / H**3,
    b01=1.5e-6 / H**3,
    b11=6.0e-6 / H**3,
    b22=2.0e-6 / H**3,
)
