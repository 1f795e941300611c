(define (domain planhrc-absolute-paper)
  (:requirements :strips :typing :equality :negative-preconditions :conditional-effects)
  (:types link joint orientation)
  (:predicates
    (connected ?j - joint ?l - link)
    (hasorientation ?o - orientation ?j - joint)
    (orientationord ?o1 - orientation ?o2 - orientation)
    (affected ?j2 - joint ?l - link ?j1 - joint))
  (:action rotateclockwise
    :parameters (?l1 - link ?l2 - link ?j1 - joint ?o1 - orientation ?o2 - orientation)
    :precondition (and
      (connected ?j1 ?l1)
      (connected ?j1 ?l2)
      (not (= ?l1 ?l2))
      (hasorientation ?o1 ?j1)
      (orientationord ?o1 ?o2))
    :effect (and
      (not (hasorientation ?o1 ?j1))
      (hasorientation ?o2 ?j1)
      (forall (?j2 - joint ?o3 - orientation ?o4 - orientation)
        (when (and
            (affected ?j2 ?l1 ?j1)
            (not (= ?j2 ?j1))
            (hasorientation ?o3 ?j2)
            (orientationord ?o3 ?o4))
          (and
            (not (hasorientation ?o3 ?j2))
            (hasorientation ?o4 ?j2))))))
  (:action rotateanticlockwise
    :parameters (?l1 - link ?l2 - link ?j1 - joint ?o1 - orientation ?o2 - orientation)
    :precondition (and
      (connected ?j1 ?l1)
      (connected ?j1 ?l2)
      (not (= ?l1 ?l2))
      (hasorientation ?o1 ?j1)
      (orientationord ?o2 ?o1))
    :effect (and
      (not (hasorientation ?o1 ?j1))
      (hasorientation ?o2 ?j1)
      (forall (?j2 - joint ?o3 - orientation ?o4 - orientation)
        (when (and
            (affected ?j2 ?l1 ?j1)
            (not (= ?j2 ?j1))
            (hasorientation ?o3 ?j2)
            (orientationord ?o4 ?o3))
          (and
            (not (hasorientation ?o3 ?j2))
            (hasorientation ?o4 ?j2)))))))
