; One action declared twice with different parameter lists. VAL reads the first declaration (a plan that uses the
; second is a "Bad plan description!"); Fast Downward, reading the text as it is, uses the second.
(define (domain twice)
  (:requirements :strips :typing)
  (:types item)
  (:predicates (ready ?x - item) (done ?x - item))
  (:action finish
    :parameters (?x - item)
    :precondition (ready ?x)
    :effect (done ?x))
  (:action finish
    :parameters (?x ?y - item)
    :precondition (and (ready ?x) (ready ?y))
    :effect (and (done ?x) (done ?y))))
