# verdant built-in tree `birch`: a slender, white-barked tree with a loose crown of drooping twigs
# (lparser 5 keyword format), written for verdant. The trunk grows three branches per step, 137°
# apart, pitched 45-55° up from the trunk and thinning 12 % a step; branches fork into twigs that
# gravity (t) bends down, each twig node with a pair of small diamond leaves (colour 8).
recursion 8
angle 22
thickness 12
min_thickness 0.4
color 12 214 208 196
color 8 96 140 52
axiom c(12)FFFA
rule A = !(0.88)F[~(15)&(50)"(0.8)B]>(137)[~(15)&(55)"(0.75)B]>(137)[~(15)&(45)"(0.7)B]>(137)F A
rule B = !(0.65)F[~(25)&(50)"(0.7)D]>(120)F[~(25)&(55)"(0.7)D]LL B
rule D = "(0.85)t(0.25)F[-(40)L][+(40)L]t(0.25)F L D
rule L = [c(8)~(40)&(50){.+(35)f.-(70)f.-(110)f.-(70)f.}]
