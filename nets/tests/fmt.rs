//! The formatter: text to model to text round trips, and `fmt` twice changes nothing.

use petrel_diag::duration::TimeUnit;
use petrel_diag::report::Diagnostics;
use petrel_diag::source::FileId;
use petrel_nets::fmt::format_file;
use petrel_nets::model::*;
use petrel_nets::syntax::parse_file;
use proptest::prelude::*;
use std::path::Path;

fn parse(text: &str) -> (NetFile, Diagnostics) {
    let mut d = Diagnostics::new();
    let f = parse_file(FileId(0), "x.pn", text, &mut d);
    (f, d)
}

fn parse_clean(text: &str) -> NetFile {
    let (f, d) = parse(text);
    assert!(d.is_empty(), "unexpected diagnostics: {d:?}\n{text}");
    f
}

const MESSY: &str = r#"// The mission net.
// Two lines of comment.
net   Mission{ place stopped=1 // initially stopped
  place ongoing place   done


  // start it
  transition start on start_mission : stopped->ongoing{activate Phases   call PLN.go( 1,2.50, -3 , "a \"quoted\" \\ text\n" ,[1,2.5e-7],true) }
  transition abort on alarm( reason : text , _ ): ongoing -> stopped {  // abort!
      deactivate Phases

      call PLN.itinerary_to_end(reason)   // trailing
      start answer after 1.5min
      start answer after delay
      cancel answer
      emit replan
      emit alarm("x", 2)
      // end of block
  }
  transition spin: ongoing->ongoing
  transition sink on go: ->
  // end of net
}
net Other {
}
// end of file
"#;

const CANONICAL: &str = r#"// The mission net.
// Two lines of comment.
net Mission {
    place stopped = 1  // initially stopped
    place ongoing
    place done

    // start it
    transition start on start_mission: stopped -> ongoing {
        activate Phases
        call PLN.go(1, 2.5, -3, "a \"quoted\" \\ text\n", [1, 2.5e-7], true)
    }
    transition abort on alarm(reason: text, _): ongoing -> stopped {  // abort!
        deactivate Phases

        call PLN.itinerary_to_end(reason)  // trailing
        start answer after 1.5min
        start answer after delay
        cancel answer
        emit replan
        emit alarm("x", 2)
        // end of block
    }
    transition spin: ongoing -> ongoing
    transition sink on go: ->
    // end of net
}

net Other {
}

// end of file
"#;

#[test]
fn messy_text_formats_to_the_canonical_layout_keeping_every_comment() {
    let model = parse_clean(MESSY);
    let text = format_file(&model);
    assert_eq!(text, CANONICAL);
    // Text to model to text: the canonical text reads back to the same model.
    assert_eq!(parse_clean(&text), model);
    assert_eq!(format_file(&parse_clean(&text)), text);
}

#[test]
fn the_model_holds_what_was_written() {
    let m = parse_clean(MESSY);
    let net = &m.nets[0];
    assert_eq!(net.name.text, "Mission");
    assert_eq!(net.places().count(), 3);
    let abort = net.transitions().nth(1).unwrap();
    let trigger = abort.trigger.as_ref().unwrap();
    assert_eq!(trigger.event.text, "alarm");
    assert_eq!(trigger.bindings[0].ty.map(|t| t.0), Some(Type::Text));
    assert_eq!(trigger.bindings[1].name.text, "_");
    assert!(matches!(
        &abort.actions[2].action,
        Action::StartTimer { after: DurationExpr::Literal { value, unit: TimeUnit::Minutes, .. }, .. } if *value == 1.5
    ));
    let start = net.transitions().next().unwrap();
    let Action::Call { args, .. } = &start.actions[1].action else {
        panic!("call expected")
    };
    assert_eq!(
        args[3],
        Expr::Text("a \"quoted\" \\ text\n".into(), Default::default())
    );
    assert_eq!(args[2], Expr::Int(-3, Default::default()));
}

#[test]
fn example_missions_are_in_canonical_layout() {
    let missions = Path::new(env!("CARGO_MANIFEST_DIR")).join("../missions");
    let mut seen = 0;
    for dir in std::fs::read_dir(missions).unwrap() {
        for file in std::fs::read_dir(dir.unwrap().path()).unwrap() {
            let path = file.unwrap().path();
            if path.extension().is_some_and(|e| e == "pn") {
                let text = std::fs::read_to_string(&path).unwrap();
                assert_eq!(
                    format_file(&parse_clean(&text)),
                    text,
                    "{} is not canonical",
                    path.display()
                );
                seen += 1;
            }
        }
    }
    assert!(seen >= 10, "net files found: {seen}");
}

/// Before: `petrel fmt` joined a file's header comment to the first net's own comment,
/// dropping the blank line that kept them apart (and any blank line between comments).
#[test]
fn blank_lines_between_comments_are_kept() {
    let text = "// The file's header.\n\n// About A.\nnet A {\n    // One.\n\n    // Two.\n    place p = 1\n\n    // The end, first part.\n\n    // The end, second part.\n}\n\n// After, one.\n\n// After, two.\n";
    let model = parse_clean(text);
    assert_eq!(
        model.nets[0].trivia.comments,
        ["The file's header.", BLANK_LINE, "About A."]
    );
    assert_eq!(format_file(&model), text);
}

// ---- properties ----

fn ident() -> impl Strategy<Value = String> {
    "[a-z][a-z0-9_]{0,6}".prop_filter("not a keyword", |s| is_identifier(s))
}

fn name() -> impl Strategy<Value = Name> {
    ident().prop_map(Name::synthetic)
}

/// A name that is not a word of guards or formulas (`and`, `or`, `not`...), for places where
/// the language reads those words as operators.
fn plain_name() -> impl Strategy<Value = Name> {
    ident()
        .prop_filter("not an operator word", |s| {
            !matches!(
                s.as_str(),
                "and" | "or" | "not" | "if" | "to" | "implies" | "active"
            )
        })
        .prop_map(Name::synthetic)
}

fn comment_text() -> impl Strategy<Value = String> {
    "[a-zA-Z0-9 ,.!?()-]{0,16}".prop_map(|s| s.trim_end().to_string())
}

fn trivia() -> impl Strategy<Value = Trivia> {
    (
        any::<bool>(),
        prop::collection::vec(comment_text(), 0..3),
        any::<bool>(),
    )
        .prop_map(|(blank_before, mut comments, apart)| {
            // A blank line between two comments is kept (never first nor last).
            if apart && comments.len() >= 2 {
                comments.insert(1, BLANK_LINE.to_string());
            }
            Trivia {
                blank_before,
                comments,
            }
        })
}

fn expr() -> impl Strategy<Value = Expr> {
    let sp = petrel_diag::source::Span::default();
    let leaf = prop_oneof![
        any::<i64>().prop_map(move |v| Expr::Int(v, sp)),
        any::<f64>()
            .prop_filter("finite", |v| v.is_finite())
            .prop_map(move |v| Expr::Float(v, sp)),
        any::<bool>().prop_map(move |v| Expr::Bool(v, sp)),
        any::<String>().prop_map(move |v| Expr::Text(v.replace('\r', ""), sp)),
        plain_name().prop_map(Expr::Var),
        plain_name().prop_map(Expr::SelfParam),
    ];
    leaf.prop_recursive(2, 8, 4, move |inner| {
        prop::collection::vec(inner, 0..4).prop_map(move |v| Expr::List(v, sp))
    })
}

fn guard() -> impl Strategy<Value = Guard> {
    let ops = prop::sample::select(vec![
        CmpOp::Eq,
        CmpOp::Ne,
        CmpOp::Lt,
        CmpOp::Le,
        CmpOp::Gt,
        CmpOp::Ge,
    ]);
    let leaf = prop_oneof![
        expr().prop_map(Guard::Value),
        (ops, expr(), expr()).prop_map(|(op, a, b)| Guard::Compare(op, a, b)),
    ];
    leaf.prop_recursive(3, 12, 2, |inner| {
        prop_oneof![
            (inner.clone(), inner.clone()).prop_map(|(a, b)| Guard::Or(Box::new(a), Box::new(b))),
            (inner.clone(), inner.clone()).prop_map(|(a, b)| Guard::And(Box::new(a), Box::new(b))),
            inner.prop_map(|a| Guard::Not(Box::new(a))),
        ]
    })
}

fn allow() -> impl Strategy<Value = Allow> {
    (0u32..1000, prop::option::of(comment_text())).prop_map(|(n, reason)| Allow {
        code: Name::synthetic(format!("W{n:04}")),
        reason,
    })
}

/// A place in an arc: a name, or a child's completion place.
fn place_ref() -> impl Strategy<Value = Name> {
    prop_oneof![
        4 => name(),
        1 => name().prop_map(|n| Name::synthetic(format!("{}.done", n.text))),
    ]
}

fn action() -> impl Strategy<Value = Action> {
    let sp = petrel_diag::source::Span::default();
    prop_oneof![
        (name(), prop::collection::vec(expr(), 0..3)).prop_map(move |(net, args)| {
            Action::Activate {
                net,
                args,
                span: sp,
            }
        }),
        name().prop_map(Action::Deactivate),
        Just(Action::Deactivate(Name::synthetic("self"))),
        Just(Action::Finish(sp)),
        name().prop_map(Action::CancelTimer),
        (name(), 0u32..100_000, 0usize..4).prop_map(move |(timer, v, u)| Action::StartTimer {
            timer,
            after: DurationExpr::Literal {
                value: v as f64 / 4.0,
                unit: TimeUnit::ALL[u],
                span: sp
            }
        }),
        (name(), name()).prop_map(|(timer, n)| Action::StartTimer {
            timer,
            after: DurationExpr::Seconds(n)
        }),
        (name(), name()).prop_map(|(timer, n)| Action::StartTimer {
            timer,
            after: DurationExpr::SelfSeconds(n)
        }),
        (name(), name(), prop::collection::vec(expr(), 0..4)).prop_map(
            move |(program, function, args)| {
                Action::Call {
                    program,
                    function,
                    args,
                    span: sp,
                }
            }
        ),
        (
            name(),
            prop::collection::vec(expr(), 0..3),
            prop::option::of(name())
        )
            .prop_map(move |(event, args, to)| Action::Emit {
                event,
                args,
                to,
                span: sp
            }),
    ]
}

fn item() -> impl Strategy<Value = Item> {
    let place = (name(), 0u32..3).prop_map(|(name, tokens)| {
        ItemKind::Place(PlaceDecl {
            name,
            tokens,
            tokens_span: None,
        })
    });
    let binding = (
        prop_oneof![name(), Just(Name::synthetic("_"))],
        prop::option::of(prop::sample::select(Type::ALL.to_vec())),
    )
        .prop_map(|(name, ty)| Binding {
            name,
            ty: ty.map(|t| (t, Default::default())),
        });
    let trigger = (name(), prop::collection::vec(binding, 0..3))
        .prop_map(|(event, bindings)| Trigger { event, bindings });
    let action_item = (trivia(), action(), prop::option::of(comment_text())).prop_map(
        |(trivia, action, trailing)| ActionItem {
            trivia,
            action,
            trailing,
        },
    );
    let transition = (
        name(),
        prop::option::of(trigger),
        prop::option::of(guard()),
        (
            prop::collection::vec(place_ref(), 0..3),
            prop::collection::vec(place_ref(), 0..2),
        ),
        prop::collection::vec(place_ref(), 0..3),
        prop::collection::vec(action_item, 0..4),
        prop::collection::vec(comment_text(), 0..2),
    )
        .prop_map(
            |(name, trigger, guard, (inputs, empty), outputs, actions, end_comments)| {
                ItemKind::Transition(TransitionDecl {
                    name,
                    trigger,
                    guard,
                    inputs,
                    empty,
                    outputs,
                    actions,
                    end_comments,
                })
            },
        );
    let child = (
        name(),
        prop::option::of(prop::collection::vec(expr(), 0..3)),
    )
        .prop_map(|(net, args)| ChildDecl { net, args });
    let children = prop::collection::vec(child, 1..3).prop_map(ItemKind::Children);
    (
        trivia(),
        prop::collection::vec(allow(), 0..2),
        prop_oneof![3 => place, 3 => transition, 1 => children],
        prop::option::of(comment_text()),
    )
        .prop_map(|(trivia, allows, kind, trailing)| Item {
            trivia,
            allows,
            kind,
            trailing,
        })
}

fn net_file() -> impl Strategy<Value = NetFile> {
    let param = (plain_name(), prop::sample::select(Type::ALL.to_vec()))
        .prop_map(|(name, ty)| Param { name, ty });
    let net = (
        trivia(),
        prop::collection::vec(allow(), 0..2),
        name(),
        prop::collection::vec(param, 0..3),
        prop::collection::vec(item(), 0..6),
        prop::collection::vec(comment_text(), 0..2),
    )
        .prop_map(
            |(trivia, allows, name, params, items, end_comments)| NetDecl {
                trivia,
                allows,
                name,
                params,
                items,
                end_comments,
            },
        );
    (
        prop::collection::vec(net, 0..3),
        prop::collection::vec(comment_text(), 0..2),
    )
        .prop_map(|(nets, end_comments)| NetFile {
            path: "x.pn".into(),
            nets,
            end_comments,
        })
}

/// What the printer cannot express by design: blank lines before the first item of a block,
/// and around nets (always one), are layout, not content.
fn normalise(mut f: NetFile) -> NetFile {
    for net in &mut f.nets {
        net.trivia.blank_before = false;
        if let Some(first) = net.items.first_mut() {
            first.trivia.blank_before = false;
        }
        for item in &mut net.items {
            if let ItemKind::Transition(t) = &mut item.kind {
                if let Some(first) = t.actions.first_mut() {
                    first.trivia.blank_before = false;
                }
            }
        }
    }
    f
}

fn strip_blank_flags(mut f: NetFile) -> NetFile {
    for net in &mut f.nets {
        net.trivia.blank_before = false;
    }
    f
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 400, ..ProptestConfig::default() })]

    /// Any model prints to text that reads back to the same model.
    #[test]
    fn model_to_text_to_model(file in net_file()) {
        let file = normalise(file);
        let text = format_file(&file);
        let (back, d) = parse(&text);
        prop_assert!(d.is_empty(), "{:?}\n{}", d, text);
        prop_assert_eq!(strip_blank_flags(back), strip_blank_flags(file));
    }

    /// `fmt` is idempotent: formatting formatted text changes nothing.
    #[test]
    fn fmt_is_idempotent(file in net_file()) {
        let once = format_file(&normalise(file));
        let twice = format_file(&parse(&once).0);
        prop_assert_eq!(twice, once);
    }

    /// Arbitrary text never makes the parser panic, and whatever parses cleanly formats to a
    /// fixpoint.
    #[test]
    fn any_text_parses_without_panic_and_formats_idempotently(
        text in r#"(net|place|transition|children|on|if|not|and|or|==|<=|>|!=|->|:|,|\{|\}|\(|\)|\[|\]|=|1|0|2\.5|30s|"t"|//c|\n| |a|b|call|emit|to|finish|self|self\.a|a\.done|@allow\(W0602\)|P\.f|start|after|cancel|activate|deactivate|\$)*"#
    ) {
        let (f, d) = parse(&text);
        if d.is_empty() {
            let once = format_file(&f);
            let twice = format_file(&parse(&once).0);
            prop_assert_eq!(twice, once);
        }
    }
}
