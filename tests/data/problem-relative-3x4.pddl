(define (problem obj1-demo)
  (:domain planhrc-relative)
  (:objects
    obj1_l1 obj1_l2 obj1_l3 - link
    obj1_j1 obj1_j2 - joint
    deg_0 deg_90 deg_180 deg_270 - orientation
  )
  (:init
    (connected obj1_j1 obj1_l1)
    (connected obj1_j1 obj1_l2)
    (connected obj1_j2 obj1_l2)
    (connected obj1_j2 obj1_l3)
    (hasorientation deg_0 obj1_j1)
    (hasorientation deg_90 obj1_j2)
    (orientationord deg_0 deg_90)
    (orientationord deg_90 deg_180)
    (orientationord deg_180 deg_270)
    (orientationord deg_270 deg_0)
  )
  (:goal (and
    (hasorientation deg_90 obj1_j2)
    (hasorientation deg_270 obj1_j1)
  ))
)

