(define (domain planhrc-relative)
  (:requirements :strips :typing :equality :negative-preconditions)
  (:types link joint orientation)
  (:predicates
    (connected ?j - joint ?l - link)
    (hasorientation ?o - orientation ?j - joint)
    (orientationord ?o1 - orientation ?o2 - orientation))
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
      (hasorientation ?o2 ?j1)))
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
      (hasorientation ?o2 ?j1))))
