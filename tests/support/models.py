"""Small models the tests build themselves: three .vm texts covering every op of the format (with numpy's run of
them, the independent truth), and a smooth blend of ellipsoids built as fidget's bear is."""

import numpy as np
import sympy
from sympy import Rational, cos, sin, sqrt

from implc import x, y, z

from . import vm_sampling
from .truth import corner_sign_changes

# every op of the format, in three small models written here
CSG = """# a box minus a sphere, unioned with a rounded bump --scale 0.8
x var-x
y var-y
z var-z
h const 0.6
ax abs x
ay abs y
az abs z
bx sub ax h
by sub ay h
bz sub az h
box max bx by
box2 max box bz
x2 square x
y2 square y
z2 square z
s0 add x2 y2
s1 add s0 z2
d sqrt s1
r const 0.75
ball sub d r
nball neg ball
cut max box2 nball
zt const 0.9
dz sub z zt
dz2 square dz
b0 add x2 y2
b1 add b0 dz2
bd sqrt b1
br const 0.3
bump sub bd br
out min cut bump
"""


BLEND = """# exp/ln/div blend with trig wiggles
x var-x
y var-y
z var-z
k const 8
x2 square x
y2 square y
z2 square z
s add x2 y2
s2 add s z2
c const 0.3
a sub s2 c
ka mul k a
e1 exp ka
xo const 0.45
xs sub x xo
xs2 square xs
t add xs2 y2
t2 add t z2
c2 const 0.08
b sub t2 c2
kb mul k b
e2 exp kb
inv div e1 e2
sum add e1 e2
one const 1
l ln sum
kk div l k
w const 0.05
sx sin x
cz cos z
wave mul sx cz
ww mul w wave
out add kk ww
"""


TANGLE = """_x var-x
_y var-y
_z var-z
_x2 square _x
_x4 square _x2
_y2 square _y
_y4 square _y2
_z2 square _z
_z4 square _z2
_5 const 5.0
_x2_5 mul _x2 _5
_y2_5 mul _y2 _5
_z2_5 mul _z2 _5
_s0 sub _x4 _x2_5
_s1 add _s0 _y4
_s2 sub _s1 _y2_5
_s3 add _s2 _z4
_s4 sub _s3 _z2_5
_10 const 10.0
_out add _s4 _10
"""


def interpret(text, x, y, z):
    """F of the .vm text at numpy arrays x, y, z (the benchmarks' numpy interpreter of the text, not
    implc's compiler): the independent truth of these tests."""
    return vm_sampling.evaluate(vm_sampling.parse(text), x, y, z)


def sign_change_cells(text, bounds, depth):
    n = 1 << depth
    axes = [np.linspace(lo, hi, n + 1) for lo, hi in bounds]
    return corner_sign_changes(interpret(text, *np.meshgrid(*axes, indexing="ij")))


def ellipsoid(centre, axes, turn):
    """An ellipsoid's implicit function: centre and semi-axes in tenths, turned by ``turn`` about z."""
    (cx, cy, cz), (ax, ay, az) = ([Rational(v, 10) for v in t] for t in (centre, axes))
    u = cos(turn) * (x - cx) - sin(turn) * (y - cy)
    v = sin(turn) * (x - cx) + cos(turn) * (y - cy)
    return sqrt((u / ax)**2 + (v / ay)**2 + ((z - cz) / az)**2) - 1


def smooth_blend():
    """Three rotated ellipsoids joined by log-sum-exp smooth minima (as fidget's bear is built): natural
    enclosures of it are loose (each exp magnifies its argument's width) and its leaves' partials need a
    few levels of splitting before they keep their sign."""
    def smooth_min(a, b, k=11):
        return -sympy.log(sympy.exp(-k * a) + sympy.exp(-k * b)) / k

    body = ellipsoid((0, 0, 0), (5, 3, 3), Rational(1, 2))
    arm = ellipsoid((4, 2, 1), (2, 4, 2), 1)
    leg = ellipsoid((-4, 3, -1), (2.5, 1.7, 4), -Rational(3, 5))
    return smooth_min(smooth_min(body, arm), leg)
