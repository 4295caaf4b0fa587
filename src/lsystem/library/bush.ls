# verdant built-in tree `bush`: a shrub of five stems from the ground, forking as they rise
# (lparser 5 keyword format), written for verdant. Each stem segment is shorter and thinner than
# the last and forks left and right with random turns; every fork carries diamond leaves (colour 8).
recursion 5
angle 26
thickness 12
min_thickness 0.5
color 12 110 86 62
color 8 58 108 44
axiom c(12)[&(25)S]>(72)[&(30)S]>(72)[&(20)S]>(72)[&(35)S]>(72)[&(28)S]
rule S = "(0.85)!(0.8)F[~(25)+(35)S L]~(15)F[~(25)-(35)S L]L
rule L = [c(8)~(50){.+(35)f.-(70)f.-(110)f.-(70)f.}]
