//! Status-bar messages: what the workbench did, or why it could not, oldest first (errors are
//! also logged to stderr, once each).

/// Most messages kept (the oldest are dropped first).
pub const MAX_MESSAGES: usize = 500;

/// One line in the status bar.
#[derive(Clone, Debug, PartialEq)]
pub struct Message {
    /// The text.
    pub text: String,
    /// True for errors.
    pub error: bool,
}

/// The messages of this session.
#[derive(Clone, Debug, Default)]
pub struct Messages {
    list: Vec<Message>,
}

impl Messages {
    /// Adds a note.
    pub fn info(&mut self, text: impl Into<String>) {
        self.push(Message {
            text: text.into(),
            error: false,
        });
    }

    /// Adds an error (and logs it to stderr).
    pub fn error(&mut self, text: impl Into<String>) {
        let text = text.into();
        crate::tell!("groovescope: {text}");
        self.push(Message { text, error: true });
    }

    /// The guard of work that cannot start while other work runs: when `busy`, adds `why` as
    /// an error. True when it refused (the caller then returns).
    pub fn refuse_if(&mut self, busy: bool, why: &str) -> bool {
        if busy {
            self.error(why);
        }
        busy
    }

    fn push(&mut self, m: Message) {
        if self.list.len() >= MAX_MESSAGES {
            self.list.remove(0);
        }
        self.list.push(m);
    }

    /// Every message kept, oldest first.
    #[must_use]
    pub fn all(&self) -> &[Message] {
        &self.list
    }

    /// The newest message.
    #[must_use]
    pub fn last(&self) -> Option<&Message> {
        self.list.last()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_refusal_says_why_and_a_free_start_says_nothing() {
        let mut m = Messages::default();
        assert!(!m.refuse_if(false, "busy"));
        assert!(m.all().is_empty());
        assert!(m.refuse_if(true, "busy"));
        let said = m.last().unwrap();
        assert!(said.error && said.text == "busy", "{said:?}");
    }
}
