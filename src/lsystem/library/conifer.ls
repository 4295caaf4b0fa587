# verdant built-in tree `conifer`: a spruce-like crown (lparser 5 keyword format), written for
# verdant. The trunk grows one whorl of five branches per step, each whorl 72° round from the last
# and 41° more for the next; the trunk thins 10 % a step. Branches leave at 105° (drooping a
# little below the horizontal), half as long per segment as the trunk; older, lower whorls have
# grown longer, so the crown is a cone. Every branch segment carries two side twigs and a
# diamond plate of needles (polygon, colour 8); random turns ~ make each seed a different tree.
recursion 10
angle 20
thickness 20
min_thickness 0.3
color 12 92 66 46
color 8 34 78 44
axiom c(12)FFA
rule A = F[&(105)"(0.5)!(0.25)B]>(72)[&(105)"(0.5)!(0.25)B]>(72)[&(105)"(0.5)!(0.25)B]>(72)[&(105)"(0.5)!(0.25)B]>(72)[&(105)"(0.5)!(0.25)B]>(41)!(0.9)A
rule B = F[-(50)"(0.8)C][+(50)"(0.8)C]~(20)N B
rule C = FN
rule N = [c(8)~(25){.+(30)f.-(60)f.-(120)f.-(60)f.}]
