(define (problem oriented-dup-4x8)
  (:domain oriented-dup)
  (:objects l1 l2 l3 l4 -link j1 j2 j3 -joint
            a0 a45 a90 a135 a180 a225 a270 a315 -angle)
  (:init
    (connected j1 l1) (connected j1 l2) (connected j2 l2) (connected j2 l3) (connected j3 l3) (connected j3 l4)
    (next-angle a0 a45) (next-angle a45 a90) (next-angle a90 a135) (next-angle a135 a180)
    (next-angle a180 a225) (next-angle a225 a270) (next-angle a270 a315) (next-angle a315 a0)
    (angle-of j1 a0) (angle-of j2 a90) (angle-of j3 a315))
  (:goal (and (angle-of j1 a90) (angle-of j2 a45) (angle-of j3 a135))))
