; A relative rotation domain written the way some benchmark files are: typed lists whose dash touches the type
; (?j -joint), :adl and :equality, a negative precondition, and two actions declared twice with other parameter
; lists. VAL reads the first declaration of each; planners must too.
(define (domain oriented-dup)
  (:requirements :strips :typing :adl :equality :negative-preconditions)
  (:types link joint angle)
  (:predicates
    (connected ?j -joint ?l -link)
    (angle-of ?j -joint ?a -angle)
    (next-angle ?a1 ?a2 -angle)
    (blocked ?j -joint))
  (:action increase_angle
    :parameters (?l1 ?l2 -link ?j -joint ?a1 ?a2 -angle)
    :precondition (and (connected ?j ?l1) (connected ?j ?l2) (not (= ?l1 ?l2)) (not (blocked ?j))
                       (angle-of ?j ?a1) (next-angle ?a1 ?a2))
    :effect (and (not (angle-of ?j ?a1)) (angle-of ?j ?a2)))
  (:action decrease_angle
    :parameters (?l1 ?l2 -link ?j -joint ?a1 ?a2 -angle)
    :precondition (and (connected ?j ?l1) (connected ?j ?l2) (not (= ?l1 ?l2)) (not (blocked ?j))
                       (angle-of ?j ?a1) (next-angle ?a2 ?a1))
    :effect (and (not (angle-of ?j ?a1)) (angle-of ?j ?a2)))
  ; later declarations: one link and the joint only
  (:action increase_angle
    :parameters (?l1 -link ?j -joint ?a1 ?a2 -angle)
    :precondition (and (connected ?j ?l1) (angle-of ?j ?a1) (next-angle ?a1 ?a2))
    :effect (and (not (angle-of ?j ?a1)) (angle-of ?j ?a2)))
  (:action decrease_angle
    :parameters (?l1 -link ?j -joint ?a1 ?a2 -angle)
    :precondition (and (connected ?j ?l1) (angle-of ?j ?a1) (next-angle ?a2 ?a1))
    :effect (and (not (angle-of ?j ?a1)) (angle-of ?j ?a2)))
)
