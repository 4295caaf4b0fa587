# verdant built-in tree `broadleaf`: a round-crowned deciduous tree (lparser 5 keyword format),
# written for verdant. The trunk (bark colour 12) carries a bud A; every bud grows a whorl of
# three shoots 137° apart, each thinner (!) and shorter (") than its parent and pitched down (&)
# by the angle, with a leaf L (colour 8, a six-point polygon) at every shoot. A random turn ~ of
# up to 15° before every shoot makes each seed a different tree.
recursion 5
angle 24
thickness 18
min_thickness 1
color 12 104 80 60
color 8 52 104 40
axiom c(12)FFFFFFA
rule A = !"[~(15)&FFL A]>(137)[~(15)&FFL A]>(137)[~(15)&FL A]
rule L = [c(8)^(40){.-z.+z.+z.-|-z.+z.+z.}]
